"""The layers as code: pyproject.toml's import-linter contracts hold (issue 32; the style's
"layers are written as an import-linter contract, never only in the docs")."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LINT = Path(sys.executable).with_name("lint-imports")


def _lint(*config: str) -> subprocess.CompletedProcess[str]:
    # Without import-linter's cache: after modules moved, a stale cache reported an import
    # of the package root that no file holds.
    return subprocess.run([str(LINT), "--no-cache", *config], cwd=ROOT, capture_output=True,
                          text=True, timeout=600, check=False)


def test_the_import_contracts_hold() -> None:
    done = _lint()
    assert done.returncode == 0, done.stdout[-4000:] + done.stderr[-2000:]
    assert "0 broken" in done.stdout and "7 kept" in done.stdout, done.stdout[-2000:]



def test_a_broken_contract_fails(tmp_path: Path) -> None:
    # The tool reads this tree and can fail: ident does import numpy.
    config = tmp_path / "broken.toml"
    config.write_text('[tool.importlinter]\nroot_package = "fsmbench"\n'
                      "include_external_packages = true\n\n"
                      "[[tool.importlinter.contracts]]\n"
                      'name = "no numpy in ident (false on purpose)"\ntype = "forbidden"\n'
                      'source_modules = ["fsmbench.ident"]\nforbidden_modules = ["numpy"]\n',
                      encoding="utf-8")
    done = _lint(str(config))
    assert done.returncode != 0 and "BROKEN" in done.stdout, done.stdout[-2000:]


def _strongly_connected(graph: dict[str, set[str]]) -> list[list[str]]:
    """Tarjan's components of more than one module (iterative: the graph has ~330 nodes)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    on_stack: set[str] = set()
    stack: list[str] = []
    out: list[list[str]] = []
    counter = 0
    for root in sorted(graph):
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = counter
                    counter += 1
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph[child]))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                comp = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    comp.append(member)
                    if member == node:
                        break
                if len(comp) > 1:
                    out.append(sorted(comp))
    return out


def _run_time_graph() -> dict[str, set[str]]:
    """fsmbench's modules and what each imports when it runs: at module level and inside
    functions (grimp sees both), not under ``TYPE_CHECKING``."""
    import grimp

    graph = grimp.build_graph("fsmbench", exclude_type_checking_imports=True)
    modules = set(graph.modules)
    return {m: set(graph.find_modules_directly_imported_by(m)) & modules for m in modules}


def test_no_module_imports_itself_round_a_cycle_at_run_time() -> None:
    cycles = _strongly_connected(_run_time_graph())
    assert cycles == [], f"{len(cycles)} import cycles: " + "; ".join(
        " <-> ".join(c) for c in cycles)


def test_the_cycle_finder_finds_a_cycle() -> None:
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}, "e": set()}
    assert _strongly_connected(graph) == [["a", "b", "c"]]


#: Where a function may import (docs/architecture.md, "Seams"): the command line's
#: ``run()`` (``fsmbench --help`` loads no numerics), the public API and the package root
#: (``import fsmbench`` loads none), the server's and the IOC's start (its port and prefix
#: checked before the bench is built) and tune's device proxy (the device reached before
#: tune's numerics).
SEAM_MODULES = ("fsmbench/cli/", "fsmbench/api.py", "fsmbench/__init__.py",
                "fsmbench/live/serve.py", "fsmbench/live/epics.py", "fsmbench/tune/proxy.py")
#: The extras: imported where they are used, so that the core imports without them.
OPTIONAL = {"dask", "distributed", "tango", "softioc", "epics", "aioca", "ophyd_async",
            "bluesky", "matplotlib", "PIL"}


def _imports(tree: ast.AST, *, in_function: bool) -> list[tuple[int, str]]:
    """``(line, module)`` of each import at module level (``in_function`` False; the bodies
    of top-level ``if``/``try`` included) or inside a function, not under TYPE_CHECKING."""
    found: list[tuple[int, str]] = []

    def walk(node: ast.AST, inside: bool) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.If) and "TYPE_CHECKING" in ast.unparse(child.test):
                continue
            deeper = inside or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef))
            if isinstance(child, ast.Import) and inside == in_function:
                found.extend((child.lineno, a.name) for a in child.names)
            elif isinstance(child, ast.ImportFrom) and inside == in_function and child.module:
                found.append((child.lineno, child.module if child.level == 0 else ""))
            if isinstance(child, (ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef,
                                  ast.If, ast.Try, ast.With)) or deeper:
                walk(child, deeper)

    walk(tree, False)
    return found


def test_imports_inside_functions_are_at_the_named_seams_only() -> None:
    src = ROOT / "src"
    trees = {".".join(p.relative_to(src).with_suffix("").parts).removesuffix(".__init__"):
             (p, ast.parse(p.read_text(encoding="utf-8"))) for p in src.rglob("*.py")}
    top = {m: {name for _line, name in _imports(tree, in_function=False)}
           for m, (_p, tree) in trees.items()}

    def brings_an_extra(module: str, seen: frozenset[str] = frozenset()) -> bool:
        while module and module not in top:
            module = module.rpartition(".")[0]
        if not module or module in seen:
            return False
        return any(name.split(".")[0] in OPTIONAL or (name.startswith("fsmbench") and
                   brings_an_extra(name, seen | {module})) for name in top[module])

    stray = [f"{p.relative_to(src)}:{line} imports {name}"
             for m, (p, tree) in sorted(trees.items())
             if not str(p.relative_to(src)).startswith(SEAM_MODULES)
             for line, name in _imports(tree, in_function=True)
             if name.split(".")[0] not in OPTIONAL and not brings_an_extra(name)]
    assert stray == [], "imports inside functions away from the seams:\n" + "\n".join(stray)


def test_the_seams_keep_their_promise_of_light_imports() -> None:
    # What the seams are for (docs/architecture.md): the package root and the command
    # line's parser load none of the numerics; tune's proxy and the server's entry module
    # load neither the engine nor python-control before they reach a device or a port.
    heavy = ("scipy", "control", "xarray", "numba", "h5py", "fsmbench.sim.engine",
             "fsmbench.live.core", "fsmbench.ident", "softioc")
    code = ("import sys\n"
            "import fsmbench, fsmbench.cli, fsmbench.tune.proxy, fsmbench.live.serve\n"
            "import fsmbench.live.epics\n"
            "fsmbench.cli.build_parser()\n"
            f"print([m for m in {heavy!r} if m in sys.modules])")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=300, check=False)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.strip() == "[]", done.stdout
