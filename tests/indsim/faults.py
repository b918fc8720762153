"""Faults a lab makes, injected into a folder of clean records (issue 30, item 6).

Each fault is a named, seeded function: :class:`Fault` ``(src, dst, seed=0)``
copies the clean folder ``src`` (indsim's layout: ``<experiment>.mat``, MATLAB
v5 column vectors, and ``truth.json``) to ``dst``, corrupts the copy as a lab
would, and returns a :class:`FaultCase` saying what was done: the fault's id,
its **true cause** (an id of :data:`CAUSES`), the files and signals touched and
a description in words. ``src`` is only read, never written: every file a
fault changes is written anew in ``dst``.

The factories (:func:`unit`, :func:`sign`, :func:`clip` …) make parametrised
faults; :func:`catalogue` is the default list, one per case of issue 30 (and
a "no fault" control), :func:`faults` the same by id. Only NumPy and SciPy are
imported: the faults know nothing of fsmbench.
"""

from __future__ import annotations

import gzip
import io
import os
import shutil
import zlib
from collections.abc import Callable, Iterable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.io import loadmat, savemat
from scipy.signal import lfilter

__all__ = ["CAUSES", "Fault", "FaultCase", "Records", "catalogue", "faults"]

Array = NDArray[np.float64]

#: True cause id -> what it is, in words. A fault has exactly one true cause.
CAUSES: dict[str, str] = {
    "none": "no fault: the clean records (a control)",
    "unit": "a signal saved in another unit (mV for V, mm or nm for m) in one file",
    "sign_flipped_in_record": "one signal negated in one file (a cable or a script, not the "
                              "bench)",
    "bench_sign": "a signal negated in every file: the bench's own sign (a mount or a "
                  "polarity), not a fault of the records",
    "dac_swap": "the Sercalo's (or the Newport's) two command channels swapped for a run: "
                "the record of one axis holds the other axis's response",
    "files_exchanged": "two runs' files exchanged (each holds the other's variables)",
    "qd_outputs_crossed": "the 4QD's two outputs exchanged (Vph <-> Vpv) in every file",
    "clipped": "a signal clipped (an amplifier or an ADC range set too low)",
    "va_jump": "a jump of the interferometer's distance (a lost fringe)",
    "stuck": "a signal frozen at a constant (a dead channel or a stalled acquisition)",
    "rate": "the time vector saved with the wrong step",
    "copies": "records that are copies of another record",
    "loop_closed_in_open_record": "a record of an open-loop experiment made with the loop "
                                  "closed",
    "loop_not_closed": "a closed-loop record made with the controller off (its output zero)",
    "duplicated_channel": "one channel recorded twice (Vpv holds Vph)",
    "mains": "mains pick-up on the 4QD outputs",
    "delayed_channel": "channels of one file delayed against the others",
    "too_short": "records too short to analyse",
    "missing_or_unreadable": "files missing or not readable as MATLAB files",
    "padded": "a record padded with zeros after its end",
    "va_noise": "the interferometer's noise larger than the bench file's model (a real "
                "bench, not a fault of the records)",
}

_HEADER = b"MATLAB 5.0 MAT-file, written by indsim.faults".ljust(116)


@dataclass(frozen=True)
class FaultCase:
    """What one fault did to one folder.

    Attributes
    ----------
    fault : str
        The fault's id (``"sign_Vph_data_uch"``).
    cause : str
        The true cause, an id of :data:`CAUSES`.
    files : tuple of str
        The records touched (file stems, ``"data_uch"``).
    signals : tuple of str
        The signals touched (empty when whole files are).
    description : str
        What was done, in words.
    seed : int
        The seed it ran with.
    """

    fault: str
    cause: str
    files: tuple[str, ...]
    signals: tuple[str, ...]
    description: str
    seed: int = 0

    def to_json(self) -> dict[str, Any]:
        """JSON-ready dict."""
        out = asdict(self)
        out["files"], out["signals"] = list(self.files), list(self.signals)
        return out


class Records:
    """The records of a faulted copy: read from the clean folder, written to the copy.

    Parameters
    ----------
    src, dst : Path
        The clean folder (read only) and the copy (written).
    """

    def __init__(self, src: Path, dst: Path) -> None:
        self.src, self.dst = src, dst
        self.touched_files: list[str] = []
        self.touched_signals: list[str] = []

    def names(self) -> list[str]:
        """The record stems present in the clean folder, sorted."""
        return sorted(p.stem for p in self.src.glob("*.mat"))

    def with_signal(self, signal: str) -> list[str]:
        """The records that hold ``signal``."""
        return [n for n in self.names() if signal in self.load(n)]

    def load(self, name: str) -> dict[str, Array]:
        """One clean record's variables as 1-D float64 arrays (a fresh copy)."""
        raw = loadmat(self.src / f"{name}.mat")
        return {k: np.array(v, dtype=np.float64).reshape(-1) for k, v in raw.items()
                if not k.startswith("__")}

    def save(self, name: str, variables: dict[str, Array], signals: Iterable[str] = ()) -> None:
        """Write ``name`` into the copy (MATLAB v5, column vectors), noting what changed."""
        path = self.dst / f"{name}.mat"
        path.unlink(missing_ok=True)  # a new file: never write through a link to the input
        buf = io.BytesIO()
        savemat(buf, {k: np.ascontiguousarray(v, dtype=np.float64).reshape(-1, 1)
                      for k, v in variables.items()}, format="5", oned_as="column")
        data = bytearray(buf.getvalue())
        data[:116] = _HEADER  # scipy's header carries the time: a fixed one, same seed same bytes
        path.write_bytes(bytes(data))
        self.touch(name, signals)

    def touch(self, name: str, signals: Iterable[str] = ()) -> None:
        """Note a record (and signals) as touched, once each, in order."""
        if name not in self.touched_files:
            self.touched_files.append(name)
        for s in signals:
            if s not in self.touched_signals:
                self.touched_signals.append(s)

    def edit(self, name: str, fn: Callable[[dict[str, Array]], dict[str, Array]],
             signals: Iterable[str]) -> None:
        """Load ``name``, apply ``fn`` to its variables, save the result."""
        self.save(name, fn(self.load(name)), signals)


Apply = Callable[[Records, np.random.Generator], None]


@dataclass(frozen=True)
class Fault:
    """A named, seeded fault: ``fault(src, dst, seed=0) -> FaultCase``.

    Attributes
    ----------
    id : str
        Name (letters, digits, ``_``).
    cause : str
        The true cause, an id of :data:`CAUSES`.
    description : str
        What it does, in words.
    apply : callable
        ``apply(records, rng)`` corrupts the copy through :class:`Records`.
    """

    id: str
    cause: str
    description: str
    apply: Apply

    def __post_init__(self) -> None:
        if self.cause not in CAUSES:
            raise ValueError(f"fault {self.id}: unknown cause {self.cause!r}")

    def __call__(self, src: Path, dst: Path, seed: int = 0) -> FaultCase:
        """Copy ``src`` to ``dst`` (absent or empty) and inject the fault into the copy."""
        src, dst = Path(src), Path(dst)
        if src.resolve() == dst.resolve():
            raise ValueError("the faulted copy must be another folder than the clean one")
        if dst.exists() and any(dst.iterdir()):
            raise FileExistsError(f"{dst} is not empty")
        dst.mkdir(parents=True, exist_ok=True)
        for p in sorted(src.iterdir()):
            if p.is_file():
                shutil.copyfile(p, dst / p.name)
        records = Records(src, dst)
        rng = np.random.default_rng([seed, zlib.crc32(self.id.encode())])
        self.apply(records, rng)
        return FaultCase(self.id, self.cause, tuple(records.touched_files),
                         tuple(records.touched_signals), self.description, seed)


# ----------------------------------------------------------------------------- helpers


def _peak(x: Array) -> float:
    return float(np.max(np.abs(x))) if x.size else 0.0


def _varied(variables: dict[str, Array], signals: Sequence[str],
            fn: Callable[[Array], Array]) -> dict[str, Array]:
    out = dict(variables)
    for s in signals:
        out[s] = fn(out[s])
    return out


# ----------------------------------------------------------------------------- factories


def none() -> Fault:
    """The clean copy (the control: nothing should be said about it)."""
    return Fault("none", "none", "the clean records, copied unchanged", lambda r, g: None)


def unit(file: str, signal: str, factor: float, words: str) -> Fault:
    """``signal`` multiplied by ``factor`` in ``file`` (``words``: "Vph in mV")."""

    def apply(r: Records, rng: np.random.Generator) -> None:
        r.edit(file, lambda v: _varied(v, [signal], lambda x: x * factor), [signal])

    return Fault(f"unit_{signal}_x{factor:g}_{file}", "unit",
                 f"{file}: {signal} saved x{factor:g} ({words})", apply)


def sign(file: str, signal: str) -> Fault:
    """``signal`` negated in ``file`` only."""

    def apply(r: Records, rng: np.random.Generator) -> None:
        r.edit(file, lambda v: _varied(v, [signal], np.negative), [signal])

    return Fault(f"sign_{signal}_{file}", "sign_flipped_in_record",
                 f"{file}: {signal} negated (in this file only)", apply)


def sign_everywhere(signal: str) -> Fault:
    """``signal`` negated in every file: a bench sign, which no record contradicts."""

    def apply(r: Records, rng: np.random.Generator) -> None:
        for name in r.with_signal(signal):
            r.edit(name, lambda v: _varied(v, [signal], np.negative), [signal])

    return Fault(f"sign_{signal}_every_file", "bench_sign",
                 f"{signal} negated in every file (what a reversed 4QD or mount polarity "
                 "records: the data are consistent)", apply)


_PAIRS = {"data_uch": ("data_ucv", {"Ucv": "Uch", "Vcv": "Vch"}),
          "data_ucv": ("data_uch", {"Uch": "Ucv", "Vch": "Vcv"}),
          "data_unh": ("data_unv", {"Unv": "Unh"}),
          "data_unv": ("data_unh", {"Unh": "Unv"})}


def dac_swap(runs: Sequence[str] = ("data_uch",)) -> Fault:
    """The two axes' cables swapped for ``runs``: each holds the other axis's response.

    ``data_uch`` then holds ``data_ucv``'s samples under ``data_uch``'s names (``Ucv``
    as ``Uch``, ``Vcv`` as ``Vch``): the command named ``Uch`` drove the v coil, and
    its monitor followed the coil (the cables from the amplifiers to the coils
    swapped).
    """

    def apply(r: Records, rng: np.random.Generator) -> None:
        for run in runs:
            other, rename = _PAIRS[run]
            v = r.load(other)
            r.save(run, {rename.get(k, k): x for k, x in v.items()}, rename.values())

    tag = "_".join(x.removeprefix("data_") for x in runs)
    return Fault(f"dac_swap_{tag}", "dac_swap",
                 f"{', '.join(runs)}: the two axes' command cables swapped for the run (each "
                 "file holds the other axis's response under its own names)", apply)


def exchange_files(a: str = "data_uch", b: str = "data_ucv") -> Fault:
    """Files ``a`` and ``b`` exchanged whole (each holds the other's variables)."""

    def apply(r: Records, rng: np.random.Generator) -> None:
        pa, pb = r.dst / f"{a}.mat", r.dst / f"{b}.mat"
        tmp = r.dst / f".{a}.exchange"
        os.replace(pa, tmp)
        os.replace(pb, pa)
        os.replace(tmp, pb)
        r.touch(a)
        r.touch(b)

    return Fault(f"exchange_{a.removeprefix('data_')}_{b.removeprefix('data_')}",
                 "files_exchanged", f"{a}.mat and {b}.mat exchanged (names swapped on disk)",
                 apply)


def crossed_qd() -> Fault:
    """``Vph`` and ``Vpv`` exchanged in every file (the 4QD's output cables crossed)."""

    def apply(r: Records, rng: np.random.Generator) -> None:
        for name in r.with_signal("Vph"):
            r.edit(name, lambda v: {**v, "Vph": v["Vpv"], "Vpv": v["Vph"]}, ["Vph", "Vpv"])

    return Fault("qd_outputs_crossed", "qd_outputs_crossed",
                 "Vph and Vpv exchanged in every file (the 4QD's output cables crossed)", apply)


def clip(file: str, signals: Sequence[str], level: float = 0.3) -> Fault:
    """``signals`` of ``file`` clipped at ``level`` of their peak (about zero)."""

    def apply(r: Records, rng: np.random.Generator) -> None:
        r.edit(file, lambda v: _varied(v, signals, lambda x: np.clip(
            x, -level * _peak(x), level * _peak(x))), signals)

    return Fault(f"clip_{'_'.join(signals)}_{file}", "clipped",
                 f"{file}: {', '.join(signals)} clipped at {100 * level:g} % of the peak", apply)


FRINGE_M = 765e-9  # the Attocube's jump of one fringe at 1530 nm (a half wavelength)


def va_jump(file: str, step_m: float = FRINGE_M) -> Fault:
    """``Va`` of ``file`` jumps by ``step_m`` at a seeded point of the record's middle fifth."""

    def apply(r: Records, rng: np.random.Generator) -> None:
        def fn(v: dict[str, Array]) -> dict[str, Array]:
            va = v["Va"].copy()
            at = int(va.size * rng.uniform(0.4, 0.6))
            va[at:] += step_m
            return {**v, "Va": va}

        r.edit(file, fn, ["Va"])

    return Fault(f"va_jump_{file}", "va_jump",
                 f"{file}: Va jumps by {1e9 * step_m:g} nm (a fringe) mid-record", apply)


def stuck(file: str, signal: str, start: float = 0.4, length: float = 0.2) -> Fault:
    """``signal`` of ``file`` frozen at its value from ``start`` for ``length`` of the record.

    ``start=0, length=1`` freezes it entirely (at its first sample).
    """

    def apply(r: Records, rng: np.random.Generator) -> None:
        def fn(x: Array) -> Array:
            y = x.copy()
            i0 = int(start * y.size)
            i1 = min(y.size, i0 + max(1, int(length * y.size)))
            y[i0:i1] = y[i0]
            return y

        r.edit(file, lambda v: _varied(v, [signal], fn), [signal])

    whole = start == 0 and length >= 1
    tag = "all" if whole else f"{100 * length:g}pc"
    what = "frozen at its first sample throughout" if whole else (
        f"frozen for {100 * length:g} % of the record from {100 * start:g} %")
    return Fault(f"stuck_{signal}_{file}_{tag}", "stuck", f"{file}: {signal} {what}", apply)


def wrong_rate(factor: float, files: Sequence[str] | None = None) -> Fault:
    """``t`` saved with its step times ``factor`` (in ``files``; default every file)."""

    def apply(r: Records, rng: np.random.Generator) -> None:
        for name in files or r.names():
            r.edit(name, lambda v: {**v, "t": v["t"][0] + (v["t"] - v["t"][0]) * factor},
                   ["t"])

    where = "every file" if files is None else ", ".join(files)
    tag = "every_file" if files is None else "_".join(f.removeprefix("data_") for f in files)
    return Fault(f"rate_x{factor:g}_{tag}", "rate",
                 f"t saved with its step x{factor:g} in {where}", apply)


def copies(targets: Sequence[int] = (2, 3, 4, 5), source: int = 1) -> Fault:
    """Huddle tests ``targets`` are byte copies of huddle test ``source``."""

    def apply(r: Records, rng: np.random.Generator) -> None:
        for t in targets:
            shutil.copyfile(r.src / f"data_huddle_test_{source}.mat",
                            r.dst / f"data_huddle_test_{t}.mat")
            r.touch(f"data_huddle_test_{t}")

    tag = "".join(str(t) for t in targets)
    return Fault(f"copies_huddle_{tag}_of_{source}", "copies",
                 f"huddle tests {', '.join(map(str, targets))} are copies of huddle test "
                 f"{source}", apply)


def loop_closed_in_open(target: int = 1, source: int = 3) -> Fault:
    """Open-loop huddle test ``target`` made of closed-loop test ``source``'s t, Vph, Vpv, Va."""

    def apply(r: Records, rng: np.random.Generator) -> None:
        v = r.load(f"data_huddle_test_{source}")
        r.save(f"data_huddle_test_{target}", {k: v[k] for k in ("t", "Vph", "Vpv", "Va")},
               ["Vph", "Vpv", "Va"])

    return Fault(f"loop_closed_in_huddle_{target}", "loop_closed_in_open_record",
                 f"data_huddle_test_{target} (open loop) recorded with the loop closed (huddle "
                 f"test {source}'s t, Vph, Vpv, Va)", apply)


def zero_controller(tests: Sequence[int] = (3, 5)) -> Fault:
    """The closed-loop huddle tests' controller outputs ``Uch``, ``Ucv`` zero throughout."""

    def apply(r: Records, rng: np.random.Generator) -> None:
        for t in tests:
            r.edit(f"data_huddle_test_{t}",
                   lambda v: _varied(v, ["Uch", "Ucv"], np.zeros_like), ["Uch", "Ucv"])

    return Fault("zero_controller_output", "loop_not_closed",
                 f"huddle tests {', '.join(map(str, tests))} (closed loop): Uch and Ucv zero "
                 "throughout, the rest as recorded", apply)


def loop_open_in_closed(pairs: Sequence[tuple[int, int]] = ((3, 2), (5, 4))) -> Fault:
    """Closed-loop huddle tests recorded with the controller off.

    Each target holds the open-loop test's ``t``, ``Vph``, ``Vpv``, ``Va`` (the same
    configuration) and ``Uch = Ucv = 0``.
    """

    def apply(r: Records, rng: np.random.Generator) -> None:
        for target, source in pairs:
            v = r.load(f"data_huddle_test_{source}")
            zero = np.zeros_like(v["t"])
            r.save(f"data_huddle_test_{target}",
                   {"t": v["t"], "Uch": zero, "Ucv": zero, "Vph": v["Vph"], "Vpv": v["Vpv"],
                    "Va": v["Va"]}, ["Uch", "Ucv", "Vph", "Vpv", "Va"])

    return Fault("loop_open_in_closed_huddle", "loop_not_closed",
                 "closed-loop huddle tests " + ", ".join(f"{t}" for t, _ in pairs)
                 + " recorded with the controller off (open-loop tests' signals, Uch = Ucv = 0)",
                 apply)


def duplicated_channel(src: str = "Vph", dst: str = "Vpv") -> Fault:
    """``dst`` holds ``src``'s samples in every file (one channel recorded twice)."""

    def apply(r: Records, rng: np.random.Generator) -> None:
        for name in r.with_signal(src):
            r.edit(name, lambda v: {**v, dst: v[src].copy()}, [dst])

    return Fault(f"{dst}_equals_{src}", "duplicated_channel",
                 f"{dst} equal to {src} in every file", apply)


def mains(freq_hz: float = 50.0, amplitude_v: float = 0.05,
          signals: Sequence[str] = ("Vph", "Vpv")) -> Fault:
    """``amplitude_v`` (peak) of ``freq_hz`` mains on ``signals`` in every file, seeded phases."""

    def apply(r: Records, rng: np.random.Generator) -> None:
        for name in r.with_signal(signals[0]):
            v = r.load(name)
            for s in signals:
                v[s] = v[s] + amplitude_v * np.sin(2 * np.pi * freq_hz * v["t"]
                                                   + rng.uniform(0, 2 * np.pi))
            r.save(name, v, signals)

    return Fault(f"mains_{freq_hz:g}hz", "mains",
                 f"{1e3 * amplitude_v:g} mV of {freq_hz:g} Hz mains on {', '.join(signals)} "
                 "in every file", apply)


def delayed(file: str = "data_uch", signals: Sequence[str] = ("Vph", "Vpv"),
            samples: int = 20) -> Fault:
    """``signals`` of ``file`` delayed by ``samples`` against the file's other channels."""

    def fn(x: Array) -> Array:
        return np.concatenate([np.full(samples, x[0]), x[:-samples]])

    def apply(r: Records, rng: np.random.Generator) -> None:
        r.edit(file, lambda v: _varied(v, signals, fn), signals)

    return Fault(f"delay_{samples}_{'_'.join(signals)}_{file}", "delayed_channel",
                 f"{file}: {', '.join(signals)} delayed by {samples} samples", apply)


def truncated(samples: int, files: Sequence[str] | None = None) -> Fault:
    """``files`` (default every file) cut to their first ``samples`` samples."""

    def apply(r: Records, rng: np.random.Generator) -> None:
        for name in files or r.names():
            r.edit(name, lambda v: {k: x[:samples] for k, x in v.items()}, [])

    where = "every file" if files is None else ", ".join(files)
    tag = "every_file" if files is None else "_".join(f.removeprefix("data_") for f in files)
    return Fault(f"short_{samples}_{tag}", "too_short",
                 f"{where}: cut to {samples} samples", apply)


def closed_loop_as(target: str = "data_uch", source: str = "data_huddle_test_3") -> Fault:
    """A closed-loop record saved as the open-loop ``target`` (``data_uch`` or ``data_ucv``).

    ``Uch`` (or ``Ucv``), ``Vph``, ``Vpv`` are the closed loop's (the target's length);
    the coil monitor the closed-loop record lacks is the target's own ``Uc -> Vc``
    response (a 16-tap FIR fitted on the clean target) applied to that ``Uc``.
    """
    uc, vc = ("Uch", "Vch") if target == "data_uch" else ("Ucv", "Vcv")

    def apply(r: Records, rng: np.random.Generator) -> None:
        clean, loop = r.load(target), r.load(source)
        n = min(clean["t"].size, loop["t"].size)
        taps = 16
        u = clean[uc]
        X = np.column_stack([np.concatenate([np.zeros(k), u[:u.size - k]])
                             for k in range(taps)])
        fir = np.linalg.lstsq(X, clean[vc], rcond=None)[0]
        r.save(target, {"t": loop["t"][:n], uc: loop[uc][:n],
                        vc: lfilter(fir, [1.0], loop[uc][:n]),
                        "Vph": loop["Vph"][:n], "Vpv": loop["Vpv"][:n]},
               [uc, vc, "Vph", "Vpv"])

    return Fault(f"closed_loop_as_{target}", "loop_closed_in_open_record",
                 f"{source} (loop closed, no excitation) saved as {target}", apply)


def missing(files: Sequence[str] = ("data_unh", "data_unv"), how: str = "deleted") -> Fault:
    """``files`` deleted, or replaced by their gzip, a FIFO, or a link to ``/dev/zero``."""
    hows = ("deleted", "gzip", "fifo", "dev_zero")
    if how not in hows:
        raise ValueError(f"how must be one of {hows}")

    def apply(r: Records, rng: np.random.Generator) -> None:
        for name in files:
            path = r.dst / f"{name}.mat"
            data = path.read_bytes()
            path.unlink()
            if how == "gzip":
                path.write_bytes(gzip.compress(data, mtime=0))
            elif how == "fifo":
                os.mkfifo(path)
            elif how == "dev_zero":
                path.symlink_to("/dev/zero")
            r.touch(name)

    words = {"deleted": "deleted", "gzip": "replaced by their gzip (same name)",
             "fifo": "replaced by a FIFO", "dev_zero": "replaced by a link to /dev/zero"}[how]
    return Fault(f"{'_'.join(f.removeprefix('data_') for f in files)}_{how}",
                 "missing_or_unreadable", f"{', '.join(files)} {words}", apply)


def padded(file: str, fraction: float = 0.3, with_t: bool = False) -> Fault:
    """``file`` padded with zeros for ``fraction`` of its length.

    ``with_t`` pads ``t`` with zeros too (a preallocated array the acquisition
    never filled); otherwise ``t`` runs on and only the signals are zero.
    """

    def apply(r: Records, rng: np.random.Generator) -> None:
        def fn(v: dict[str, Array]) -> dict[str, Array]:
            t = v["t"]
            n = max(1, int(fraction * t.size))
            dt = float(np.median(np.diff(t)))
            out = {k: np.concatenate([x, np.zeros(n)]) for k, x in v.items()}
            if not with_t:
                out["t"] = np.concatenate([t, t[-1] + dt * np.arange(1, n + 1)])
            return out

        r.edit(file, fn, [])

    tag = "_with_t" if with_t else ""
    return Fault(f"padded_{file}{tag}", "padded",
                 f"{file}: {100 * fraction:g} % of zeros appended to every signal"
                 + (" and to t" if with_t else " (t runs on)"), apply)


def va_noise(rms_m: float = 1e-6) -> Fault:
    """White noise of ``rms_m`` added to ``Va`` in every file (a noisy but real Attocube)."""

    def apply(r: Records, rng: np.random.Generator) -> None:
        for name in r.with_signal("Va"):
            r.edit(name, lambda v: {**v, "Va": v["Va"] + rms_m * rng.standard_normal(
                v["Va"].size)}, ["Va"])

    return Fault(f"va_noise_{1e6 * rms_m:g}um", "va_noise",
                 f"{1e6 * rms_m:g} um rms of white noise on Va in every file (a real "
                 "interferometer noisier than the bench file says)", apply)


# ----------------------------------------------------------------------------- catalogue


def catalogue() -> list[Fault]:
    """Every case of issue 30's rounds, each once, and the clean control first."""
    return [
        none(),
        unit("data_uch", "Vph", 1e3, "Vph in mV"),
        unit("data_cal_pd_h", "Vph", 1e-3, "Vph in kV, or a gain of 1e-3"),
        unit("data_uch", "Uch", 1e3, "Uch in mV"),
        unit("data_huddle_test_1", "Va", 1e3, "Va in mm"),
        unit("data_huddle_test_2", "Va", 1e9, "Va in nm"),
        sign("data_uch", "Vph"),
        sign("data_ucv", "Vpv"),
        sign("data_uch", "Uch"),
        sign("data_ucv", "Ucv"),
        sign("data_uch", "Vch"),
        sign("data_ucv", "Vcv"),
        sign("data_unh", "Unh"),
        sign("data_cal_pd_h", "Vnh"),
        sign("data_rep_h", "Vph"),
        sign_everywhere("Vph"),
        dac_swap(("data_uch",)),
        dac_swap(("data_uch", "data_ucv")),
        dac_swap(("data_unh",)),
        exchange_files("data_uch", "data_ucv"),
        crossed_qd(),
        clip("data_uch", ["Vch"]),
        clip("data_uch", ["Vph", "Vpv"]),
        clip("data_unh", ["Vph", "Vpv"]),
        va_jump("data_huddle_test_1"),
        va_jump("data_rep_h"),
        stuck("data_uch", "Vph"),
        stuck("data_huddle_test_2", "Va", start=0.0, length=1.0),
        stuck("data_unv", "Vpv", start=0.0, length=1.0),
        wrong_rate(2.0),
        wrong_rate(0.5),
        wrong_rate(2.0, ["data_uch"]),
        copies((2, 3, 4, 5)),
        copies((2, 4)),
        loop_closed_in_open(1, 3),
        zero_controller((3, 5)),
        loop_open_in_closed(((3, 2), (5, 4))),
        duplicated_channel("Vph", "Vpv"),
        mains(50.0),
        mains(60.0),
        delayed("data_uch", ("Vph", "Vpv"), 20),
        truncated(10),
        truncated(2, ["data_rep_h"]),
        closed_loop_as("data_uch", "data_huddle_test_3"),
        missing(how="deleted"),
        missing(how="gzip"),
        missing(how="fifo"),
        missing(how="dev_zero"),
        padded("data_uch"),
        padded("data_huddle_test_1", with_t=True),
        va_noise(1e-6),
    ]


def faults() -> dict[str, Fault]:
    """:func:`catalogue` by id (ids are unique)."""
    out: dict[str, Fault] = {}
    for f in catalogue():
        if f.id in out:
            raise ValueError(f"duplicate fault id {f.id}")
        out[f.id] = f
    return out
