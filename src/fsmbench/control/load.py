"""Read back the controllers ``fsmbench design`` writes, as discrete state-space models.

Two files hold them (:mod:`fsmbench.control.export`):

* ``controllers.mat``: per controller a struct ``{K, Kd}`` of state-space
  structs, plus an ``fsmbench`` struct (sample time, discretisation, the 4QD
  gain, the list of controllers). The discrete ``Kd`` is taken as it is.
* ``controllers_sos.json`` (format ``fsmbench.controllers_sos`` version 2): per
  controller and axis (``h``, ``v``) a cascade of discrete second-order
  sections. Each section is realised on its own (two states at most, from its
  six coefficients, never from the product polynomial of the whole cascade,
  whose coefficients lose the lightly damped notches to rounding); the
  sections are cascaded and the two axes put side by side (block diagonal).

Messages name the file, the key or variable and what is wrong, never the file's bytes
(a value, a decoder's excerpt, a header): the live device answers its clients with them,
and a file that is not a controllers file must not reach them through its words.

Both give a :class:`~fsmbench.control.controller.Controller`: ``x[k+1] = a x[k] + b r[k]``,
``v[k] = c x[k] + d r[k]``, from the beam angle ``r = [Rh, Rv]`` [rad] to
``v = [Uch, Ucv]`` [V] for the bench's feedback controllers. The sign
convention is the design's: the loop is closed as ``u = -K y``, i.e. the
command applied is ``-v``; the matrices are ``K``'s, the sign is the user's to
apply. The measured 4QD voltage ``Vp`` [V] becomes ``r = Vp / Gd`` with
``Gd = gd_v_per_rad``, the file's (None when it records none). Each is named as in the
file, its ``source`` is the file's path.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fsmbench.control.controller import BEAM_ANGLES, SERCALO_COMMANDS, Controller
from fsmbench.control.export import SOS_FORMAT, SOS_FORMAT_VERSION
from fsmbench.control.study import CONTROLLERS_MAT, CONTROLLERS_SOS_JSON
from fsmbench.io.errors import RecordingError
from fsmbench.io.matfile import load_mat

__all__ = [
    "BEAM_ANGLES",
    "DEFAULT_CONTROLLER",
    "SERCALO_COMMANDS",
    "load_controllers",
    "select_controller",
]

#: The controller :func:`select_controller` picks when none is named: fsmbench's own design.
DEFAULT_CONTROLLER = "fsmbench_controller"
_AXES = ("h", "v")
# Sample times are doubles written by fsmbench; a caller's 1/fs computed another way
# may differ from the stored value by rounding only.
_TS_RTOL = 1e-9

FloatArray = NDArray[np.float64]


# --------------------------------------------------------------------------- reading
def load_controllers(path: str | os.PathLike[str], *, ts_s: float | None = None,
                     max_states: int | None = None) -> dict[str, Controller]:
    """Every controller of a ``controllers.mat`` or ``controllers_sos.json``.

    Parameters
    ----------
    path : str or os.PathLike
        The file (its kind is told from its content, not its name), or a
        ``fsmbench design`` output folder: then its ``controllers.mat``, or
        ``controllers_sos.json`` if there is no MAT-file.
    ts_s : float, optional
        The sample time the caller runs at, s; when given, the file's must
        equal it (to rounding).
    max_states : int, optional
        Refuse a controller of more states, before it is realised (a caller that
        must answer in bounded time: a cascade's realisation grows as its cube).

    Returns
    -------
    dict of str to Controller
        In the file's own order (``controllers.mat`` also holds the IFF
        controller, ``Vch, Vcv -> Uch, Ucv``, and the Newport one,
        ``Rh, Rv -> Unh, Unv``; see :func:`select_controller`).

    Raises
    ------
    RecordingError
        (a ``ValueError``) One line, ``"<file>: <problem>"``: the file does not
        exist, is not a controllers file written by ``fsmbench design`` (what
        was found, in words), is malformed, has more than ``max_states`` states,
        or its sample time is not ``ts_s``.
    """
    p = _resolve(Path(path))
    with open(p, "rb") as fh:
        head = fh.read(4096).lstrip()
    out = (_from_sos_json(p, max_states) if head[:1] in (b"{", b"[")
           else _from_mat(p, max_states))
    if not out:
        raise RecordingError(p, "lists no controllers")
    if ts_s is not None:
        want = float(ts_s)
        if not (math.isfinite(want) and want > 0.0):
            raise ValueError(f"the sample time to check against must be positive, in s; got "
                             f"{ts_s!r}")
        for k in out.values():
            _check_ts(p, k.ts_s, want)
    return out


def select_controller(controllers: Mapping[str, Controller], name: str | None = None,
                      *, inputs: Sequence[str] = BEAM_ANGLES,
                      outputs: Sequence[str] = SERCALO_COMMANDS) -> Controller:
    """The controller to run: the one named, or by default fsmbench's own design.

    Parameters
    ----------
    controllers : mapping of str to Controller
        As :func:`load_controllers` returns them (the file's order).
    name : str, optional
        The controller wanted. None picks :data:`DEFAULT_CONTROLLER`
        (``"fsmbench_controller"``, the loop-shaped controller ``fsmbench
        design`` writes) if the file has it, else the first controller, in the
        file's order, that maps ``inputs`` to ``outputs``.
    inputs, outputs : sequence of str, optional
        The signals the caller's loop needs, by default the beam angle
        ``Rh, Rv`` [rad] to the Sercalo commands ``Uch, Ucv`` [V].

    Returns
    -------
    Controller

    Raises
    ------
    RecordingError
        (a ``ValueError``) One line naming the file: the name is not in it
        (the names it holds are listed), the named controller maps other
        signals, or no controller maps ``inputs`` to ``outputs``.
    """
    if not controllers:
        raise ValueError("no controllers to choose from")
    first = next(iter(controllers.values()))
    src = Path(first.source)  # the file, as load_controllers names it
    want = f"{', '.join(inputs)} to {', '.join(outputs)}"
    if name is not None:
        if name not in controllers:
            raise RecordingError(src, f"has no controller {name!r}; it holds: "
                                 + ", ".join(controllers))
        chosen = controllers[name]
        if not chosen.maps(inputs, outputs):
            raise RecordingError(
                src, f"controller {name!r} maps {', '.join(chosen.input_names)} to "
                f"{', '.join(chosen.output_names)}; this loop needs {want}")
        return chosen
    fitting = [k for k in controllers.values() if k.maps(inputs, outputs)]
    if not fitting:
        held = "; ".join(f"{k.name} ({', '.join(k.input_names)} to {', '.join(k.output_names)})"
                         for k in controllers.values())
        raise RecordingError(src, f"has no controller from {want}; it holds: {held}")
    return next((k for k in fitting if k.name == DEFAULT_CONTROLLER), fitting[0])


# --------------------------------------------------------------------------- helpers
def _resolve(p: Path) -> Path:
    if p.is_dir():
        for candidate in (CONTROLLERS_MAT, CONTROLLERS_SOS_JSON):
            if (p / candidate).is_file():
                return p / candidate
        raise RecordingError(p, f"is a folder without {CONTROLLERS_MAT} or "
                             f"{CONTROLLERS_SOS_JSON} (the files fsmbench design writes)")
    if not p.is_file():
        raise RecordingError(p, "does not exist (expected a controllers.mat or "
                             "controllers_sos.json written by fsmbench design)")
    return p


def _check_ts(p: Path, file_ts: float, want: float) -> None:
    if not math.isclose(file_ts, want, rel_tol=_TS_RTOL, abs_tol=0.0):
        raise RecordingError(
            p, f"holds controllers sampled every {file_ts:.6g} s ({1.0 / file_ts:.6g} Hz), "
            f"but they would run every {want:.6g} s ({1.0 / want:.6g} Hz)")


def _positive_ts(p: Path, value: Any, where: str) -> float:
    try:
        ts = float(np.asarray(value, dtype=float).reshape(()))
    except (TypeError, ValueError):
        raise RecordingError(p, f"{where}: the sample time is not a number (a "
                             f"{type(value).__name__})") from None
    if not (math.isfinite(ts) and ts > 0.0):
        raise RecordingError(p, f"{where}: the sample time is {ts:g} s; a discrete controller "
                             "needs a positive one")
    return ts


def _check_states(p: Path, n: int, name: str, max_states: int | None) -> None:
    if max_states is not None and n > max_states:
        raise RecordingError(p, f"controller {name!r} has up to {n} states, more than the "
                             f"{max_states} this loop takes")


# --------------------------------------------------------------------------- controllers.mat
def _from_mat(p: Path, max_states: int | None) -> dict[str, Controller]:
    try:
        data = load_mat(p)
    except RecordingError as exc:
        # The reader's particulars may quote the file's first bytes: only its kind, which
        # has none ("is empty (0 bytes)").
        why = exc.kind or "cannot be read as a MAT-file"
        raise RecordingError(p, "is not a controllers file fsmbench reads (a controllers_sos "
                             f"JSON document or a MAT-file from fsmbench design): it {why}"
                             ) from None
    meta = data.get("fsmbench")
    if not isinstance(meta, dict) or "controllers" not in meta:
        raise RecordingError(p, "is not a controllers file written by fsmbench design: it has "
                             f"no 'fsmbench' struct listing the controllers (it holds "
                             f"{len(data)} other variables)")
    names = meta["controllers"]
    names = [names] if isinstance(names, str) else [str(n) for n in names]
    gd = meta.get("qd_gain_v_per_rad")
    gain = None
    if isinstance(gd, dict) and all(a in gd for a in _AXES):
        gain = (float(np.squeeze(gd["h"])), float(np.squeeze(gd["v"])))
    method = meta.get("discretisation", "")
    out: dict[str, Controller] = {}
    for name in names:
        entry = data.get(name)
        kd = entry.get("Kd") if isinstance(entry, dict) else None
        if not isinstance(kd, dict):
            raise RecordingError(p, f"lists controller {name!r} but has no discrete model "
                                 f"{name}.Kd")
        a, b, c, d = _mat_matrices(p, kd, name)
        _check_states(p, a.shape[0], name, max_states)
        ins = _names(p, kd.get("InputName"), b.shape[1], f"{name}.Kd.InputName")
        outs = _names(p, kd.get("OutputName"), c.shape[0], f"{name}.Kd.OutputName")
        desc = kd.get("Description", "")
        out[name] = Controller(
            name=name, description=desc if isinstance(desc, str) else "",
            ts_s=_positive_ts(p, kd.get("Ts"), f"{name}.Kd"), a=a, b=b, c=c, d=d,
            input_names=ins, output_names=outs, source_path=p, source=str(p), gd_v_per_rad=gain,
            discretisation=method if isinstance(method, str) else "")
    return out


def _mat_matrices(p: Path, kd: dict[str, Any],
                  name: str) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    missing = [x for x in "ABCD" if x not in kd]
    if missing:
        raise RecordingError(p, f"{name}.Kd has no field {', '.join(missing)}")
    try:
        a, b, c, d = (np.atleast_2d(np.array(kd[x], dtype=float)) for x in "ABCD")
    except (TypeError, ValueError):
        raise RecordingError(p, f"{name}.Kd holds a non-numeric matrix") from None
    n = a.shape[0] if a.size else 0
    p_out, m_in = d.shape
    if n == 0 and b.size == 0 and c.size == 0:  # a static gain: MATLAB keeps 0-by-m shapes loosely
        a, b, c = np.zeros((0, 0)), np.zeros((0, m_in)), np.zeros((p_out, 0))
    if a.shape != (n, n) or b.shape != (n, m_in) or c.shape != (p_out, n):
        raise RecordingError(
            p, f"{name}.Kd has inconsistent sizes: A {a.shape}, B {b.shape}, C {c.shape}, "
            f"D {d.shape}")
    if not all(np.all(np.isfinite(x)) for x in (a, b, c, d)):
        raise RecordingError(p, f"{name}.Kd holds NaN or infinite values")
    return a, b, c, d  # Controller keeps read-only copies


def _names(p: Path, value: Any, count: int, where: str) -> tuple[str, ...]:
    items = [value] if isinstance(value, str) else list(value) if value is not None else []
    out = tuple(str(x) for x in items)
    if len(out) != count:
        raise RecordingError(p, f"{where} names {len(out)} signals for {count} channels")
    return out


# --------------------------------------------------------------------------- controllers_sos.json
def _from_sos_json(p: Path, max_states: int | None) -> dict[str, Controller]:
    # Where a document fails, never the decoder's excerpt of it (module notes).
    try:
        doc = json.loads(p.read_bytes().decode("utf-8"))
    except json.JSONDecodeError as exc:
        raise RecordingError(p, f"is not valid JSON (line {exc.lineno}, column {exc.colno})"
                             ) from None
    except UnicodeDecodeError as exc:
        raise RecordingError(p, f"is not UTF-8 text (byte {exc.start})") from None
    except RecursionError:
        raise RecordingError(p, "is not a controllers file: its JSON nests too deeply") from None
    if not isinstance(doc, dict):
        found = f"a JSON {type(doc).__name__}"
    elif doc.get("format") != SOS_FORMAT:
        found = "another 'format'" if "format" in doc else "no 'format' key"
    else:  # fsmbench's own format: its version, when it is a number, is no one's secret
        version = doc.get("format_version")
        found = (f"format {SOS_FORMAT!r} version {version}"
                 if isinstance(version, int) and not isinstance(version, bool)
                 else "another 'format_version'")
    if (not isinstance(doc, dict) or doc.get("format") != SOS_FORMAT
            or doc.get("format_version") != SOS_FORMAT_VERSION):
        raise RecordingError(p, f"is not a controllers file: expected format {SOS_FORMAT!r} "
                             f"version {SOS_FORMAT_VERSION}, found {found}")
    ts = _positive_ts(p, doc.get("sample_time_s"), "sample_time_s")
    gain = None
    try:
        gd = doc["input_scaling"]["qd_gain_v_per_rad"]
        gain = (float(gd["h"]), float(gd["v"]))
    except (KeyError, TypeError, ValueError):
        pass  # the scaling is optional to the loader
    method = doc.get("discretisation", {})
    method = method.get("method", "") if isinstance(method, dict) else ""
    entries = doc.get("controllers")
    if not isinstance(entries, dict):
        raise RecordingError(p, "has no 'controllers' object")
    out: dict[str, Controller] = {}
    for name, entry in entries.items():
        if max_states is not None and isinstance(entry, dict):
            # At most two states a section: counted before anything is realised.
            n = sum(2 * len(chan["sos"]) for chan in (entry.get(a) for a in _AXES)
                    if isinstance(chan, dict) and isinstance(chan.get("sos"), list))
            _check_states(p, n, name, max_states)
        parts, ins, outs, rows = [], [], [], []
        for axis in _AXES:
            chan = entry.get(axis) if isinstance(entry, dict) else None
            if not isinstance(chan, dict) or "sos" not in chan:
                raise RecordingError(p, f"controller {name!r} has no sections for axis {axis}")
            parts.append(_cascade(p, chan["sos"], f"controller {name!r}, axis {axis}", ts_s=ts))
            rows.append(np.array(chan["sos"], dtype=float))  # checked by _cascade
            rows[-1].setflags(write=False)
            ins.append(_signal_name(chan.get("input_signal")))
            outs.append(_signal_name(chan.get("output_signal")))
        a, b, c, d = (_block_diag([x[i] for x in parts]) for i in range(4))
        out[str(name)] = Controller(
            name=str(name), description=str(entry.get("description", "")), ts_s=ts, a=a, b=b,
            c=c, d=d, input_names=tuple(ins), output_names=tuple(outs), source_path=p,
            source=str(p), gd_v_per_rad=gain, discretisation=str(method), sections=tuple(rows))
    return out


def _signal_name(value: Any) -> str:
    return str(value.get("name", "")) if isinstance(value, dict) else ""


def _block_diag(blocks: Sequence[FloatArray]) -> FloatArray:
    """Blocks on the diagonal; blocks with a zero dimension keep their other one."""
    rows = sum(x.shape[0] for x in blocks)
    cols = sum(x.shape[1] for x in blocks)
    out = np.zeros((rows, cols))
    i = j = 0
    for x in blocks:
        out[i:i + x.shape[0], j:j + x.shape[1]] = x
        i, j = i + x.shape[0], j + x.shape[1]
    return out


def _section_ss(row: FloatArray, *,
                eps_min: float) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Minimal realisation of ``(b0 + b1 q + b2 q^2) / (1 + a1 q + a2 q^2)``, ``q = z^-1``.

    Second order: in the controllable canonical form ``x1 = x2[k+1]`` the
    states of poles near ``z = 1`` (integrators, slow poles at a fast rate) are
    nearly equal and their coupling is O(1); evaluating or running it loses
    ``1/|z - 1|^2`` (the SOS form's own weakness, 1e-5 relative at 1 Hz for the
    fsmbench controller's four integrators at 10 kHz). The "delta" basis
    ``s = x2``, ``e = (x1 - x2) / eps`` instead gives
    ``A = [[1, eps], [-D(1)/eps, -(1 + a1)]]`` (``D(1) = 1 + a1 + a2 =
    (1 - p1)(1 - p2)``), coupling ``eps = sqrt|D(1)|`` ~ the poles' distance
    from 1, as the design's own cascade (:func:`fsmbench.bench.sections.tustin_cascade`)
    whose states are scaled in the continuous domain. First order when
    ``b2 = a2 = 0``; static when also ``b1 = a1 = 0``.
    """
    b0, b1, b2, a0, a1, a2 = row
    b0, b1, b2, a1, a2 = b0 / a0, b1 / a0, b2 / a0, a1 / a0, a2 / a0
    d = np.array([[b0]])
    r1 = b1 - b0 * a1  # strictly proper part: (r1 q + r2 q^2) / (1 + a1 q + a2 q^2)
    if b2 == 0.0 and a2 == 0.0:
        if b1 == 0.0 and a1 == 0.0:
            return np.zeros((0, 0)), np.zeros((0, 1)), np.zeros((1, 0)), d
        return np.array([[-a1]]), np.array([[1.0]]), np.array([[r1]]), d
    den_1 = (1.0 + a1) + a2  # D(1), small for poles near z = 1
    num_1 = (b0 + b1) + b2  # N(1); r1 + r2 = N(1) - b0 D(1)
    eps = max(math.sqrt(abs(den_1)), eps_min)
    return (np.array([[1.0, eps], [-den_1 / eps, -(1.0 + a1)]]), np.array([[0.0], [1.0 / eps]]),
            np.array([[num_1 - b0 * den_1, r1 * eps]]), d)


def _cascade(p: Path, sos: Any, where: str, *,
             ts_s: float) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """State space of a cascade of sections, section 0 first (SISO).

    Each section realised on its own (:func:`_section_ss`), then in series:
    ``A`` is block lower-triangular.
    """
    try:
        rows = np.array(sos, dtype=float)
    except (TypeError, ValueError):
        raise RecordingError(p, f"{where}: the sections are not a list of numbers") from None
    if rows.ndim != 2 or rows.shape[1] != 6 or rows.shape[0] == 0:
        raise RecordingError(p, f"{where}: expected sections of 6 coefficients "
                             f"[b0, b1, b2, a0, a1, a2], got an array of shape {rows.shape}")
    if not np.all(np.isfinite(rows)) or np.any(rows[:, 3] == 0.0):
        raise RecordingError(p, f"{where}: a section holds NaN, infinite values or a0 = 0")
    a, b, c, d = np.zeros((0, 0)), np.zeros((0, 1)), np.zeros((1, 0)), np.eye(1)
    for row in rows:
        # Integrators (D(1) = 0) get the design's scaling floor, 1 rad/s times ts.
        a2, b2, c2, d2 = _section_ss(row, eps_min=ts_s * 1.0)
        # Series: the section's input is the cascade's output so far.
        a = np.block([[a, np.zeros((a.shape[0], a2.shape[0]))], [b2 @ c, a2]])
        b = np.vstack([b, b2 @ d])
        c = np.hstack([d2 @ c, c2])
        d = d2 @ d
    return a, b, c, d
