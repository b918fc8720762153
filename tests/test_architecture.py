"""The layers as code: pyproject.toml's import-linter contracts hold (issue 32; the style's
"layers are written as an import-linter contract, never only in the docs")."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LINT = Path(sys.executable).with_name("lint-imports")


def _lint(*config: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([str(LINT), *config], cwd=ROOT, capture_output=True, text=True,
                          timeout=600, check=False)


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
