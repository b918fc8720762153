"""A confusion matrix of fsmbench's diagnoses (issue 30, item 6).

Every fault of ``tests/indsim/faults.py`` (unit, sign, swap, crossed 4QD
outputs, clip, jump, stuck, wrong rate, copies, the loop left closed, … and the
clean control) is injected into every bench of the independent simulator's
corpus (optionally also fsmbench's own twin benches), and fsmbench is run on
the faulted copy exactly as a user would (``fsmbench study --data FAULTED
--out OUT``; ``--mode identify`` runs ``fsmbench identify`` instead, ``--mode
budget`` ``fsmbench budget``). What fsmbench said is collected as
*statements*: every failed check (name, subject, advice), every finding (key,
message, alternatives), every notice, every skipped step, record or part, the
fallbacks, the verdict, and the error line of a run that stopped. Each
statement is mapped to **named causes** by :data:`CAUSE_PATTERNS` (regular
expressions on its words; a finding's alternatives are matched one by one and
count as "among the alternatives"), and marked when it gives **data-changing
advice** (:data:`ADVICE_PATTERNS`: negate, swap … back, divide, multiply,
rescale, exchange, flip, "set t = …", "save t …").

A statement the bench's clean control also makes (same kind, id, subject and
named causes; the numbers may differ) is *baseline*: it is what fsmbench says
about that bench, not about the fault, and is left out of the fault's row. The
verdict and the fallbacks repeat the other statements' words and are not
classified; the verdict is counted apart (``meets``: a faulted bench that
"meets its specifications"). A run that crashes names ``crash``, one killed
after ``--timeout`` ``hang``. Then, per case:

* **named**: the true cause is among the causes of the non-baseline
  statements (alone or among alternatives); for a signal negated in every file
  (true cause ``bench_sign``) also when the control's bench-sign finding is
  gone (the fault undid a sign of the bench's own); for the clean control: no
  failed check, no error and no data-changing advice;
* **wrong advice**: a statement gives data-changing advice and the true
  cause is not among the causes it names (itself or among its alternatives):
  following it would change data for a wrong reason (the issue's bar: 0; on
  the clean control every data-changing advice is wrong). ``wrong_advice_single``
  keeps those that name one cause alone. Advice that names no cause of the
  table counts as ``unclassified``, also wrong;
* **false alarms**: on the clean control, every failed check (and, listed
  apart, the identification steps it skipped: a good bench refused).

The tables: true cause (rows) × named cause (columns), counts of cases (a
case counts once in every column it names; ``(nothing)``: no new statement
names a cause); per fault the share of benches where the true cause is named
(the issue's bar: 95 %), the wrong-advice count, the runs that stopped, the
``meets`` verdicts and the causes named most; the clean control's false alarms
per bench. Printed as Markdown, written to ``OUT/diagnosis_matrix.md`` and
``OUT/diagnosis_matrix.json`` (with every case's classification, its
wrong advice and its ``unclassified`` statements).

Every finished case is cached in ``OUT/cases/<mode>/<bench>/<fault>.json``
with the raw statements (the classification is recomputed from them on every
run, so editing the pattern table needs no rerun); a case is computed again
only when its configuration (duration scale, seed, mode, bench file, the
fault's description, the hash of fsmbench's sources) changed, or with
``--force``. ``--stale-ok`` keeps cases computed with other fsmbench sources.

Run::

    PYTHONPATH=src:tests python benchmarks/diagnosis_matrix.py OUT \\
        [--bench NAME ...] [--fault ID ...] [--duration-scale 0.2] [--seed 1] \\
        [--mode study|identify|budget] [--jobs 1] [--twin default real stiff soft] \\
        [--twin-duration 20] [--corpus DIR] [--timeout 900] [--keep] [--force] \\
        [--list] [--report-only]

A full run (19 benches × 51 faults) is long: at duration scale 0.2 a study
takes 20–45 s, and 6 benches × 51 faults took 58 min with ``--jobs 2`` on a
shared 2-CPU machine (``--mode identify``: ~10 s a case). fs5k and fs20k run
at another rate than the packaged bench file's; ``--params`` gives every case
another bench file.
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import io
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from collections import Counter, defaultdict
from collections.abc import Iterable, Sequence
from concurrent.futures import ThreadPoolExecutor, as_completed
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
for _p in (ROOT / "src", ROOT / "tests"):
    if str(_p) not in sys.path:
        sys.path.insert(0, str(_p))

from indsim.faults import CAUSES, Fault, faults  # noqa: E402

FORMAT = ("fsmbench_bench.diagnosis_matrix", 1)
MODES = ("study", "identify", "budget")
TWIN_PARAMS = {"default": ROOT / "src/fsmbench/bench/default_bench.toml",
               "real": ROOT / "src/fsmbench/bench/real_bench.toml",
               "stiff": ROOT / "tests/data/benches/stiff_bench.toml",
               "soft": ROOT / "tests/data/benches/soft_bench.toml"}
NAMED_BAR = 0.95

# ----------------------------------------------------------------------------- the tables

#: Named cause -> regular expressions (case-insensitive) on a statement's words: its id
#: (check name, finding key …) and its message and advice. The subject (files, signals)
#: and a check's value and limit are left out: they name no cause ("limit ≤ 0.001 m rms
#: (the bench moves by nm to µm)" is not a unit diagnosis). The first group are the true
#: causes of tests/indsim/faults.py; the second, causes fsmbench names that no fault
#: injects (a departure from the bench file, a model that misses, a weak excitation …).
#: A statement may name several; a finding's alternatives are matched one by one.
#: Phrases are fsmbench's own (benchmarks' JSON lists the statements no pattern matched,
#: ``unclassified``, to extend this table).
CAUSE_PATTERNS: dict[str, tuple[str, ...]] = {
    "sign_flipped_in_record": (
        r"recorded with its sign flipped", r"\bsign flipped\b", r"negate that signal",
        r"signs? applied when saving", r"\ba sign of the channel\b",
        r"\b(?:negated|flipped|reversed|inverted) in (?:this|that|one) (?:file|record)"),
    "bench_sign": (
        r"opposite (?:sign|polarity)", r"\bpolarity\b", r"\bmount(?:ed)? the other way",
        r"a divisor of sign", r"\bor of the device itself\b",
        r"\bthe other way (?:from|round)\b"),
    "unit": (
        r"(?<!compensation )\bunits?\b", r"\bnot in (?:volts|metres)\b",
        r"\bin (?:mV|mm|nm|µm|kV)\b", r"looks like (?:nano|micro|milli|kilo)", r"\bmV for V\b",
        r"\bmm for m\b", r"\bsave \w+ in (?:metres|volts)\b", r"\bva_in_metres\b"),
    "dac_swap": (
        r"\bDAC cables?(?: are| were)? swapped", r"swapped DAC cable", r"drove the other axis",
        r"drive each other's axis", r"swept the other axis", r"\bcables? \([^)]*\) or the two",
        r"\bdrive cables? \([^)]*\) (?:exchanged|swapped)", r"\blikely a swap\b"),
    "files_exchanged": (
        r"other axis's run saved as", r"\bor the two (?:\w+ )?files\b",
        r"\bfiles? (?:are |were )?(?:exchanged|swapped|mixed up)"),
    "qd_outputs_crossed": (
        r"4QD(?:'s)? outputs? (?:are |were )?(?:crossed|swapped|exchanged)",
        r"\bVph and Vpv (?:are |were )?(?:crossed|swapped|exchanged)",
        r"\bcrossed (?:4QD )?outputs", r"4QD(?:'s)? (?:output )?cables? (?:are |were )?"
        r"(?:crossed|swapped)", r"\b4QD channel is\b[^.;:]*\bswapped\b"),
    "clipped": (r"\bclip", r"\bsaturat", r"\brails?\b", r"\bflat tops?\b"),
    "va_jump": (r"\bjumps?\b", r"\bfringe", r"\blost count\b", r"\bdiscontinu",
                r"\bva_continuous\b"),
    "stuck": (r"\bconstant at\b", r"\bstuck\b", r"\bfrozen\b", r"\bchannel is dead\b",
              r"\bnot connected\b", r"\bdoes not vary\b"),
    "rate": (r"\bsampling[_ ]rates?\b", r"\brate_vs_controller\b", r"\bt steps at\b",
             r"\bt (?:was )?saved with (?:the|another) step", r"\banother rate\b",
             r"\bsampled at\b", r"\bfs_hz\b"),
    "copies": (r"\bcop(?:y|ies) of\b", r"\bidentical (?:to|records|files|samples)",
               r"\bsame samples\b", r"\bduplicates? of\b"),
    "loop_closed_in_open_record": (
        r"\bloop (?:was |is )?(?:closed|running|on) (?:in|during|while|when)\b",
        r"\brecorded with the loop closed\b", r"\bclosed[- ]loop record saved as\b",
        r"\bnot (?:an )?open[- ]loop record\b"),
    "loop_not_closed": (
        r"\bloop (?:was |is )?(?:not closed|open|off)\b", r"\bcontroller (?:was )?off\b",
        r"\bcontroller(?:'s)? output is zero\b", r"\bnot (?:a )?closed[- ]loop record\b",
        r"\bno controller output\b"),
    "duplicated_channel": (r"\bduplicat", r"\bVpv (?:is |equals |holds )(?:a copy of )?Vph",
                           r"\bsame channel\b", r"\bidentical channels?\b",
                           r"\bequal to Vph\b", r"\bholds the same samples as\b",
                           r"\bone channel recorded twice\b"),
    "mains": (r"\bmains\b", r"\b(?:50|60) Hz (?:line|pick-?up|hum)", r"\bhum\b",
              r"\bline frequency\b"),
    "delayed_channel": (r"\bdelayed (?:by|against)\b", r"\bchannels? (?:are )?(?:misaligned|"
                        r"shifted|skewed)", r"\bsamples? late\b", r"\bout of step\b",
                        r"\bchannels? (?:were|was) delayed\b"),
    "too_short": (r"\btoo short\b", r"\bnothing left after\b", r"\bnot enough samples\b",
                  r"\bneeds? at least\b", r"\bshorter than\b"),
    "missing_or_unreadable": (
        r"\bmissing\b", r"\bno data_\w+\.mat\b", r"\bnot a MAT-file\b", r"\bgzip\b",
        r"\bnamed pipe\b", r"\bFIFO\b", r"\bcharacter device\b", r"/dev/",
        r"\bnot a recording file\b", r"\bcannot (?:be )?read\b", r"\bunreadable\b",
        r"\bwas not used\b", r"\bnot in the recordings\b", r"\bno open-loop huddle test\b"),
    "padded": (r"\bpadd", r"\btrailing zeros\b", r"\bnot increasing\b",
               r"\bzeros? (?:at|after) the end\b", r"\bnon-?monotonic\b"),
    "va_noise": (r"\battocube_noise", r"\bAttocube's (?:fitted )?floor\b",
                 r"\binterferometer\b.{0,60}\bnois", r"\b(?:interferometer|Attocube)(?:'s)? noise"),
    # causes no fault injects
    "departure": (r"\bfrom the bench file's\b", r"×\s*the bench file's\b",
                  r"\bnot the bench file's\b", r"\bdeparts from\b"),
    "wrong_channel": (r"\bwrong channel\b", r"\ba gain or a channel that changed\b",
                      r"\ba gain changed by\b"),
    "model_disagrees": (r"\bdoes not predict\b", r"\bfit misses\b", r"\bnot trusted\b",
                        r"\bmodel explains -?\d", r"\bnot a line\b", r"\bmodel_validation\b",
                        r"\bdid not converge\b", r"\bband probably misses\b"),
    "uc_not_controller": (r"\bnot the quantised output of the controller\b",),
    "excitation": (r"\bexcitation level\b", r"\bexcitation on\b",
                   r"\bno power in the excitation\b", r"\bcoherence\b.{0,80}\btoo low\b"),
    "sensor_lag": (r"\b4QD amplifier lag\b", r"\b4QD amplifier not the bench file's\b",
                   r"\bquad_diode\.bandwidth"),
    "unstable": (r"\bdoes not stabilise\b",),
}

#: Statement kinds that name a cause by themselves (whatever their words).
KIND_CAUSES = {"bug": "crash", "timeout": "hang"}
#: Statement kinds kept but not classified: they repeat the others' words (the verdict's
#: "missing: a bench identified from …" names no missing file). The verdict is tabulated
#: apart (a faulted bench that "meets its specifications" passed without the evidence).
SUMMARIES = ("verdict", "fallback")

#: Data-changing advice: the user is told (or plainly invited) to change the samples or
#: the time vector. "1000× too large" counts: it invites a rescale. Advice that changes the
#: bench file ("set converter.fs_hz = …") or asks for a new record does not.
ADVICE_PATTERNS: tuple[str, ...] = (
    r"\bnegate\b", r"\bswap (?:them|it|\w+ and \w+) back\b", r"\bswap back\b",
    r"\bdivide\b", r"\bmultiply\b", r"\brescale\b", r"\bexchange (?:them|the|\w+ and)\b",
    r"\bflip (?:it|the|its|that)\b", r"\bset t\s*=", r"\bsave t\b",
    r"\bsave \w+ in (?:metres|volts)\b", r"\b(?:V|U|t)\w* = \w+\s*[*/]",
    r"\bcut the record\b", r"\b\d[\d.e+-]*× too (?:large|small)\b",
)

_CAUSE_RE = {c: re.compile("|".join(f"(?:{p})" for p in ps), re.IGNORECASE)
             for c, ps in CAUSE_PATTERNS.items()}
_ADVICE_RE = re.compile("|".join(f"(?:{p})" for p in ADVICE_PATTERNS), re.IGNORECASE)
_NUMBER_RE = re.compile(r"[-+]?\d[\d.,]*(?:e[-+]?\d+)?", re.IGNORECASE)


def causes_in(text: str) -> list[str]:
    """The named causes whose patterns match ``text``, in table order."""
    return [c for c, rx in _CAUSE_RE.items() if rx.search(text)]


def advice_in(text: str) -> list[str]:
    """The data-changing phrases of ``text`` (empty: none)."""
    return [m.group(0) for m in _ADVICE_RE.finditer(text)]


# ----------------------------------------------------------------------------- statements


@dataclass
class Statement:
    """One thing fsmbench said about a case.

    Attributes
    ----------
    kind : str
        ``check`` (failed), ``finding``, ``notice``, ``skipped`` (a step),
        ``skipped_record``, ``part_skipped``, ``fallback``, ``warning``,
        ``verdict``, ``error`` (the run stopped: its error line), ``bug`` (a
        traceback), ``timeout``.
    id : str
        The check's name, the finding's key, the notice's kind, the step …
    subject : str
        File and signal.
    text : str
        The words (message, advice).
    alternatives : list of str
        A finding's other explanations.
    detail : str
        What is kept for a reader but not classified: a check's value and limit
        (a limit's words, "the bench moves by nm to µm", name no cause).
    """

    kind: str
    id: str
    subject: str
    text: str
    alternatives: list[str] = field(default_factory=list)
    detail: str = ""

    def signature(self) -> tuple[str, str, str, tuple[str, ...]]:
        """Identity across runs: kind, id, subject and the causes named.

        A check or a finding is the same when it names the same causes, whatever its
        numbers (a 4QD gain "1.01× the bench file's" in the control and "of the
        opposite polarity" in the fault are two statements); other kinds compare
        their words with the numbers left out.
        """
        causes = tuple(sorted({*self.causes(), *self.alternative_causes()}))
        if self.kind in ("check", "finding"):
            return self.kind, self.id, self.subject, causes
        return self.kind, self.id, _NUMBER_RE.sub("#", f"{self.subject} {self.text}"), causes

    def causes(self) -> list[str]:
        """Causes named by the statement itself (its kind, id and words)."""
        own = causes_in(f"{self.id} {self.text}")
        return [KIND_CAUSES[self.kind], *own] if self.kind in KIND_CAUSES else own

    def alternative_causes(self) -> list[str]:
        """Causes named only among its alternatives."""
        own = set(self.causes())
        return [c for c in dict.fromkeys(c for a in self.alternatives for c in causes_in(a))
                if c not in own]

    def advice(self) -> list[str]:
        """Its data-changing phrases."""
        return advice_in(" ".join([self.text, *self.alternatives]))

    def to_json(self) -> dict[str, Any]:
        """JSON-ready dict."""
        return {"kind": self.kind, "id": self.id, "subject": self.subject, "text": self.text,
                "alternatives": list(self.alternatives), "detail": self.detail}

    @classmethod
    def from_json(cls, d: dict[str, Any]) -> Statement:
        """The inverse of :meth:`to_json`."""
        return cls(d["kind"], d["id"], d["subject"], d["text"], list(d.get("alternatives", [])),
                   d.get("detail", ""))


def _read_json(path: Path) -> dict[str, Any] | None:
    try:
        out = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    return out if isinstance(out, dict) else None


def _check_statement(c: dict[str, Any]) -> Statement:
    return Statement("check", str(c.get("name", "")), str(c.get("subject", "")),
                     str(c.get("advice", "")),
                     detail=f"value {c.get('value')} {c.get('unit', '')}, limit {c.get('limit')}")


def collect(out_dir: Path, status: int | None, stderr: str) -> list[Statement]:
    """Everything fsmbench said in ``out_dir`` (any of its JSON files) and its error line.

    Parameters
    ----------
    out_dir : Path
        The command's output folder (absent when it stopped).
    status : int or None
        Its exit status (None: killed after the timeout).
    stderr : str
        Its standard error.
    """
    found: list[Statement] = []
    summary = _read_json(out_dir / "summary.json") or {}
    ident = _read_json(out_dir / "identification.json") or {}
    budget = _read_json(out_dir / "budget.json") or {}
    checks = [*summary.get("failed_checks", []),
              *(c for c in ident.get("checks", []) if not c.get("passed", True)),
              *(c for c in budget.get("checks", []) if not c.get("passed", True)),
              *(c for c in budget.get("plant_checks", []) if not c.get("passed", True))]
    found += [_check_statement(c) for c in checks]
    messages = []
    for f in ident.get("findings", []):
        found.append(Statement("finding", str(f.get("key", "")), str(f.get("subject", "")),
                               str(f.get("message", "")), [str(a) for a in
                                                           f.get("alternatives", [])]))
        messages.append(str(f.get("message", "")))
    for text in summary.get("findings", []):
        if not any(m and m in text for m in messages):
            found.append(Statement("finding", "summary", "", str(text)))
    for n in [*summary.get("notices", []), *ident.get("notices", []),
              *budget.get("notices", [])]:
        found.append(Statement("notice", str(n.get("kind", "")), str(n.get("subject", "")),
                               str(n.get("message", ""))))
    diag = ident.get("diagnostics", {}) if isinstance(ident.get("diagnostics"), dict) else {}
    for step, why in (diag.get("skipped") or {}).items():
        found.append(Statement("skipped", str(step), "", str(why)))
    for w in diag.get("warnings") or []:
        found.append(Statement("warning", "identification", "", str(w)))
    for rec, why in (summary.get("skipped") or {}).items():
        found.append(Statement("skipped_record", str(rec), str(rec), str(why)))
    for p in [*summary.get("parts_skipped", []), *budget.get("skipped", [])]:
        found.append(Statement("part_skipped", str(p.get("stage", "budget")),
                               str(p.get("part", "")), str(p.get("reason", ""))))
    for text in summary.get("fallbacks", []):
        found.append(Statement("fallback", "", "", str(text)))
    if summary:
        found.append(Statement("verdict", str(summary.get("verdict_status", "")), "",
                               str(summary.get("verdict", ""))))
    if status is None:
        found.append(Statement("timeout", "", "", "the run did not finish"))
    elif status != 0:
        lines = [ln for ln in stderr.strip().splitlines() if ln.strip()]
        if status == 2:
            last = next((ln for ln in reversed(lines) if ": error: " in ln),
                        lines[-1] if lines else "")
            found.append(Statement("error", "2", "", last.split(": error: ", 1)[-1]))
        else:  # a traceback: the exception's own line says what broke
            raised = [ln.strip() for ln in lines if re.match(r"^[\w.]+(?:Error|Exception)\b", ln)]
            found.append(Statement("bug", str(status), "", raised[-1] if raised else "",
                                   detail="\n".join(lines[-12:])))
    unique: dict[tuple[str, str, str, str], Statement] = {}
    for s in found:
        unique.setdefault((s.kind, s.id, s.subject, s.text), s)
    return list(unique.values())


# ----------------------------------------------------------------------------- running


@dataclass(frozen=True)
class Config:
    """What a cached case depends on."""

    duration_scale: float
    seed: int
    mode: str
    params: str
    sources: str

    def to_json(self) -> dict[str, Any]:
        """JSON-ready dict."""
        return dict(self.__dict__)


def sources_hash() -> str:
    """sha256 of fsmbench's Python sources (a cached case is stale when they change)."""
    h = hashlib.sha256()
    for p in sorted((ROOT / "src" / "fsmbench").rglob("*.py")):
        h.update(p.relative_to(ROOT).as_posix().encode())
        h.update(p.read_bytes())
    return h.hexdigest()[:16]


def _env(single_thread: bool = False) -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT / "src"), str(ROOT / "tests"),
                                         *filter(None, [env.get("PYTHONPATH")])])
    if single_thread:  # parallel cases: one BLAS thread each, not jobs × cores fighting
        for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
            env.setdefault(var, "1")
    return env


_RUNNER = "import sys\nfrom fsmbench.cli import main\nsys.exit(main(sys.argv[1:]))\n"


def command(mode: str, data: Path, out: Path, params: Path | None) -> list[str]:
    """fsmbench's argv for ``mode`` on ``data``."""
    argv = (["study", "--data", str(data), "--out", str(out)] if mode == "study"
            else [mode, str(data), "--out", str(out)])
    return argv + (["--params", str(params)] if params is not None else [])


def run_fsmbench(argv: Sequence[str], *, timeout_s: float, in_process: bool = False,
                 single_thread: bool = False) -> tuple[int | None, str]:
    """Run fsmbench; its exit status (None after ``timeout_s``) and standard error.

    A separate process by default: a case that hangs (a FIFO read) is killed
    without taking the harness with it. ``in_process`` (the tests) saves the
    imports. ``single_thread`` runs BLAS on one thread (cases run in parallel);
    it changes a few diagnostics' last digits, no diagnosis.
    """
    if in_process:
        from fsmbench.cli import main

        err = io.StringIO()
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            status = main(list(argv))
        return status, err.getvalue()
    with subprocess.Popen([sys.executable, "-c", _RUNNER, *argv], env=_env(single_thread),
                          stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                          start_new_session=True) as proc:
        try:
            _, err = proc.communicate(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)  # its own session: only what it started
            _, err = proc.communicate()
            return None, err
        return proc.returncode, err


def run_case(bench: str, clean: Path, fault: Fault, work: Path, cfg: Config, *,
             params: Path | None = None, timeout_s: float = 900.0, keep: bool = False,
             in_process: bool = False, single_thread: bool = False) -> dict[str, Any]:
    """Inject ``fault`` into ``clean``, run fsmbench on the copy, return the case (raw).

    The faulted copy and fsmbench's output go under ``work`` and are removed
    afterwards unless ``keep``.
    """
    data, out = work / "data", work / "out"
    shutil.rmtree(work, ignore_errors=True)
    work.mkdir(parents=True)
    t0 = time.perf_counter()
    case = fault(clean, data, seed=cfg.seed)
    status, err = run_fsmbench(command(cfg.mode, data, out, params), timeout_s=timeout_s,
                               in_process=in_process, single_thread=single_thread)
    statements = collect(out, status, err)
    if not keep:
        shutil.rmtree(work, ignore_errors=True)
    return {"format": FORMAT[0], "format_version": FORMAT[1], "bench": bench,
            "config": cfg.to_json(), "case": case.to_json(), "status": status,
            "seconds": round(time.perf_counter() - t0, 1),
            "statements": [s.to_json() for s in statements]}


def cached_case(path: Path, cfg: Config, fault: Fault, *, stale_ok: bool) -> dict[str, Any] | None:
    """The cached case at ``path`` when it was computed with ``cfg`` (and this fault)."""
    case = _read_json(path)
    if case is None or case.get("case", {}).get("description") != fault.description:
        return None
    got = dict(case.get("config", {}))
    want = cfg.to_json()
    if stale_ok:
        got.pop("sources", None)
        want.pop("sources")
    return case if got == want else None


# ----------------------------------------------------------------------------- benches


def prepare_corpus(names: Iterable[str], root: Path, *, seed: int, duration_scale: float
                   ) -> dict[str, Path]:
    """Write the named corpus benches under ``root`` (kept when already there, same run)."""
    import indsim

    corpus = indsim.corpus()
    out = {}
    for name in names:
        folder = root / name
        truth = _read_json(folder / "truth.json")
        if truth is None or truth.get("seed") != seed or truth.get(
                "duration_scale") != duration_scale:
            shutil.rmtree(folder, ignore_errors=True)
            indsim.write_bench(indsim.simulate_bench(corpus[name], seed=seed,
                                                     duration_scale=duration_scale), folder)
        out[name] = folder
    return out


def prepare_twins(names: Iterable[str], root: Path, *, seed: int, duration_s: float
                  ) -> dict[str, Path]:
    """fsmbench's own twin benches (``fsmbench simulate --params``), as recorded data.

    ``twin_truth.json`` is renamed ``truth.json``: a recorded folder has no truth
    fsmbench reads.
    """
    out = {}
    for name in names:
        folder = root / f"twin_{name}"
        mark = _read_json(folder / "truth.json")
        if mark is None or mark.get("harness") != {"seed": seed, "duration_s": duration_s}:
            shutil.rmtree(folder, ignore_errors=True)
            status, err = run_fsmbench(["simulate", str(folder), "--duration", str(duration_s),
                                        "--seed", str(seed), "--params",
                                        str(TWIN_PARAMS[name])], timeout_s=3600)
            if status != 0:
                raise RuntimeError(f"fsmbench simulate {name}: {err.strip()[-400:]}")
            truth = json.loads((folder / "twin_truth.json").read_text())
            truth["harness"] = {"seed": seed, "duration_s": duration_s}
            (folder / "truth.json").write_text(json.dumps(truth))
            (folder / "twin_truth.json").unlink()
        out[f"twin_{name}"] = folder
    return out


# ----------------------------------------------------------------------------- evaluation


def evaluate(case: dict[str, Any], control: dict[str, Any] | None) -> dict[str, Any]:
    """Classify one case's statements against its bench's clean control (module notes)."""
    true = case["case"]["cause"]
    statements = [Statement.from_json(s) for s in case["statements"]]
    is_control = true == "none" and case["case"]["fault"] == "none"
    base = set() if control is None or is_control else {
        Statement.from_json(s).signature() for s in control["statements"]}
    new = [s for s in statements if s.signature() not in base and s.kind not in SUMMARIES]
    named: Counter[str] = Counter()
    alternatives: set[str] = set()
    wrong, single, unclassified = [], [], []
    for s in new:
        own, alts = s.causes(), s.alternative_causes()
        named.update(own)
        alternatives.update(alts)
        if not own and not alts:
            unclassified.append(s.to_json())
        phrases = s.advice()
        if phrases and true not in (*own, *alts):
            entry = {**s.to_json(), "advice": phrases, "causes": own + alts or ["unclassified"]}
            wrong.append(entry)
            if len(own) + len(alts) <= 1:
                single.append(entry)
    failed = [s for s in statements if s.kind == "check"]
    stopped = [s for s in statements if s.kind in ("error", "bug", "timeout")]
    if is_control:
        ok = not failed and not stopped and not wrong
    else:
        ok = true in named or true in alternatives
        if true == "bench_sign" and control is not None:
            # a signal negated in every file can undo a sign of the bench's own: then the
            # control's bench-sign finding is gone, and saying nothing is right
            signatures = {s.signature() for s in statements}
            ok = ok or any("bench_sign" in s.causes() and s.signature() not in signatures
                           for s in map(Statement.from_json, control["statements"]))
    return {"bench": case["bench"], "fault": case["case"]["fault"], "cause": true,
            "named": ok, "named_causes": sorted(named), "alternative_causes": sorted(
                alternatives - set(named)), "wrong_advice": wrong, "wrong_advice_single": single,
            "unclassified": unclassified, "failed_checks": [s.to_json() for s in failed],
            "skipped_steps": [f"{s.id}: {s.text}" for s in statements if s.kind == "skipped"],
            "status": case["status"], "verdict": next(
                (s.id for s in statements if s.kind == "verdict"), ""),
            "stopped": [s.text for s in stopped]}


def tabulate(results: list[dict[str, Any]]) -> dict[str, Any]:
    """The confusion matrix, per-fault shares, false alarms (JSON-ready)."""
    matrix: dict[str, Counter[str]] = defaultdict(Counter)
    cases: Counter[str] = Counter()
    per_fault: dict[str, dict[str, Any]] = {}
    for r in results:
        cases[r["cause"]] += 1
        row = matrix[r["cause"]]
        shown = set(r["named_causes"]) | set(r["alternative_causes"])
        row.update(shown or {"(nothing)"})
        pf = per_fault.setdefault(r["fault"], {"cause": r["cause"], "benches": 0, "named": 0,
                                               "wrong_advice": 0, "wrong_advice_single": 0,
                                               "said": Counter(), "stopped": 0,
                                               "verdicts": Counter(),
                                               "not_named_on": []})
        pf["benches"] += 1
        pf["named"] += bool(r["named"])
        pf["wrong_advice"] += bool(r["wrong_advice"])
        pf["wrong_advice_single"] += bool(r["wrong_advice_single"])
        pf["stopped"] += bool(r["stopped"])
        pf["verdicts"][r["verdict"] or ("stopped" if r["stopped"] else "none")] += 1
        pf["said"].update(shown or {"(nothing)"})
        if not r["named"]:
            pf["not_named_on"].append(r["bench"])
    for pf in per_fault.values():
        pf["share_named"] = pf["named"] / pf["benches"]
        pf["meets_bar"] = pf["share_named"] >= NAMED_BAR and pf["wrong_advice"] == 0
        pf["said"] = dict(pf["said"].most_common())
        pf["verdicts"] = dict(pf["verdicts"].most_common())
    alarms = {r["bench"]: [f"{s['id']} ({s['subject']}): {s['text'][:200]}"
                           for s in r["failed_checks"]] + r["stopped"]
              for r in results if r["fault"] == "none"}
    # not failed checks, but a clean bench's step left out is a good bench refused
    refused = {r["bench"]: [t[:200] for t in r["skipped_steps"]]
               for r in results if r["fault"] == "none" and r["skipped_steps"]}
    return {"matrix": {c: dict(row) for c, row in matrix.items()}, "cases_per_cause": dict(cases),
            "per_fault": per_fault, "false_alarms": alarms, "refused_on_clean": refused}


def markdown(table: dict[str, Any]) -> str:
    """The tables as Markdown."""
    rows = [c for c in CAUSES if c in table["matrix"]]
    cols = [c for c in [*CAUSES, *CAUSE_PATTERNS, *KIND_CAUSES.values(), "(nothing)"]
            if any(c in table["matrix"][r] for r in rows)]
    cols = list(dict.fromkeys(cols))
    short = {c: c.replace("_", " ") for c in cols}
    lines = ["### True cause (rows) × named cause (columns), cases", "",
             "| true cause | cases | " + " | ".join(short[c] for c in cols) + " |",
             "|---|---:|" + "---:|" * len(cols)]
    for r in rows:
        cells = []
        for c in cols:
            n = table["matrix"][r].get(c, 0)
            cells.append(f"**{n}**" if c == r and n else (str(n) if n else "·"))
        lines.append(f"| {r} | {table['cases_per_cause'][r]} | " + " | ".join(cells) + " |")
    lines += ["", "### Per fault", "",
              "| fault | true cause | benches | named | share | wrong advice | stopped | "
              "meets | said most |", "|---|---|---:|---:|---:|---:|---:|---:|---|"]
    for fid, pf in table["per_fault"].items():
        said = ", ".join(f"{c} {n}" for c, n in list(pf["said"].items())[:4])
        mark = "" if pf["meets_bar"] else " ✗"
        lines.append(f"| {fid} | {pf['cause']} | {pf['benches']} | {pf['named']} | "
                     f"{100 * pf['share_named']:.0f} %{mark} | {pf['wrong_advice']} | "
                     f"{pf['stopped']} | {pf['verdicts'].get('meets', 0)} | {said} |")
    lines += ["", "### False alarms on the clean control", ""]
    for bench, alarms in table["false_alarms"].items():
        lines.append(f"* {bench}: " + ("none" if not alarms else "; ".join(alarms)))
    if table["refused_on_clean"]:
        lines += ["", "Identification steps skipped on the clean control (a good bench "
                  "refused):", ""]
        lines += [f"* {bench}: " + "; ".join(steps)
                  for bench, steps in table["refused_on_clean"].items()]
    return "\n".join(lines) + "\n"


# ----------------------------------------------------------------------------- main


def _case_path(out: Path, mode: str, bench: str, fault: str) -> Path:
    return out / "cases" / mode / bench / f"{fault}.json"


def run_matrix(out: Path, benches: dict[str, Path], chosen: Sequence[Fault], cfg: Config, *,
               params: Path | None = None, jobs: int = 1, timeout_s: float = 900.0,
               keep: bool = False, force: bool = False, stale_ok: bool = False,
               in_process: bool = False, say: Any = print) -> list[dict[str, Any]]:
    """Every fault × every bench (cached); the raw cases, control first per bench."""
    todo, done = [], {}
    order = [f for f in chosen if f.id == "none"] + [f for f in chosen if f.id != "none"]
    for bench in benches:
        for fault in order:
            path = _case_path(out, cfg.mode, bench, fault.id)
            hit = None if force else cached_case(path, cfg, fault, stale_ok=stale_ok)
            if hit is None:
                todo.append((bench, fault))
            else:
                done[bench, fault.id] = hit
    say(f"{len(done)} cases cached, {len(todo)} to run ({jobs} at a time)")

    def one(bench: str, fault: Fault) -> dict[str, Any]:
        work = out / "work" / cfg.mode / bench / fault.id
        case = run_case(bench, benches[bench], fault, work, cfg, params=params,
                        timeout_s=timeout_s, keep=keep, in_process=in_process,
                        single_thread=jobs > 1)
        path = _case_path(out, cfg.mode, bench, fault.id)
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(".part")
        tmp.write_text(json.dumps(case, indent=1))
        tmp.replace(path)  # a case is either whole or absent
        return case

    with ThreadPoolExecutor(max_workers=max(1, jobs)) as pool:
        futures = {pool.submit(one, b, f): (b, f.id) for b, f in todo}
        for n, fut in enumerate(as_completed(futures), 1):
            b, fid = futures[fut]
            case = fut.result()
            done[b, fid] = case
            say(f"[{n}/{len(todo)}] {b} {fid}: status {case['status']}, "
                f"{len(case['statements'])} statements, {case['seconds']} s")
    return [done[b, f.id] for b in benches for f in order if (b, f.id) in done]


def evaluate_all(cases: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """:func:`evaluate` each case against its bench's control."""
    controls = {c["bench"]: c for c in cases if c["case"]["fault"] == "none"}
    return [evaluate(c, controls.get(c["bench"])) for c in cases]


def main(argv: list[str] | None = None) -> int:
    """Command line (module notes)."""
    import indsim

    catalogue = faults()
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("out", type=Path, nargs="?")
    parser.add_argument("--bench", nargs="*", default=None,
                        help="corpus benches (default: all of indsim.corpus())")
    parser.add_argument("--twin", nargs="*", default=[], choices=sorted(TWIN_PARAMS),
                        help="also fsmbench's own twin benches (fsmbench simulate --params)")
    parser.add_argument("--twin-duration", type=float, default=20.0,
                        help="twin record length [s]")
    parser.add_argument("--fault", nargs="*", default=None,
                        help="fault ids (default: all; the control 'none' is always run)")
    parser.add_argument("--duration-scale", type=float, default=0.2)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--mode", choices=MODES, default="study")
    parser.add_argument("--identify-only", action="store_true", help="same as --mode identify")
    parser.add_argument("--params", type=Path, default=None,
                        help="bench file for every case (default: the packaged one)")
    parser.add_argument("--jobs", type=int, default=1)
    parser.add_argument("--timeout", type=float, default=900.0, help="per case [s]")
    parser.add_argument("--corpus", type=Path, default=None,
                        help="where the clean benches are (written there when absent)")
    parser.add_argument("--keep", action="store_true", help="keep faulted data and outputs")
    parser.add_argument("--force", action="store_true", help="recompute cached cases")
    parser.add_argument("--stale-ok", action="store_true",
                        help="reuse cases computed with other fsmbench sources")
    parser.add_argument("--report-only", action="store_true",
                        help="tabulate the cached cases, run nothing")
    parser.add_argument("--list", action="store_true", help="list the faults and exit")
    args = parser.parse_args(argv)
    if args.list:
        for f in catalogue.values():
            print(f"{f.id:40s} {f.cause:28s} {f.description}")
        return 0
    if args.out is None:
        parser.error("OUT is required")
    unknown = [f for f in args.fault or [] if f not in catalogue]
    if unknown:
        parser.error(f"unknown faults {unknown}; --list shows them")
    mode = "identify" if args.identify_only else args.mode
    chosen = [catalogue["none"], *(catalogue[f] for f in args.fault or catalogue
                                   if f != "none")]
    names = args.bench if args.bench is not None else list(indsim.corpus())
    cfg = Config(args.duration_scale, args.seed, mode,
                 str(args.params) if args.params else "packaged", sources_hash())
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    corpus_dir = args.corpus or out / "corpus"
    if args.report_only:
        benches = {n: corpus_dir / n for n in names}
        benches.update({f"twin_{n}": corpus_dir / f"twin_{n}" for n in args.twin})
        cases = [c for b in benches for f in chosen
                 if (c := _read_json(_case_path(out, mode, b, f.id))) is not None]
    else:
        benches = prepare_corpus(names, corpus_dir, seed=args.seed,
                                 duration_scale=args.duration_scale)
        benches.update(prepare_twins(args.twin, corpus_dir, seed=args.seed,
                                     duration_s=args.twin_duration))
        cases = run_matrix(out, benches, chosen, cfg, params=args.params, jobs=args.jobs,
                           timeout_s=args.timeout, keep=args.keep, force=args.force,
                           stale_ok=args.stale_ok,
                           say=lambda m: print(m, file=sys.stderr, flush=True))
    results = evaluate_all(cases)
    table = tabulate(results)
    text = markdown(table)
    print(text)
    (out / "diagnosis_matrix.md").write_text(text)
    (out / "diagnosis_matrix.json").write_text(json.dumps(
        {"format": FORMAT[0], "format_version": FORMAT[1], "config": cfg.to_json(),
         "benches": list(benches), "faults": [f.id for f in chosen],
         "causes": CAUSES, "cause_patterns": CAUSE_PATTERNS,
         "advice_patterns": list(ADVICE_PATTERNS), **table, "cases": results}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
