"""Controllers for MATLAB and for a real-time target (seed 9.3, 10.3).

* :func:`write_controllers_mat`: ``controllers.mat`` with one struct per
  controller, each holding the continuous ``K`` and the Tustin ``Kd`` as
  structs of state-space matrices (``A, B, C, D, InputName, OutputName, Ts``),
  as the seed's ``save('mat/K_diag.mat', 'K', 'Kd')`` keeps them. In MATLAB:
  ``s = load('controllers.mat'); K = ss(s.fsmbench_controller.K.A, ...)``.
* :func:`sos_document` / :func:`write_sos_json`: each diagonal channel as
  second-order sections of the Tustin-discretised transfer function, the
  form an IIR filter on the real-time target runs, with the sample time.

Sign: every controller here is closed as ``u = -K y`` (the seed's
``connect(sys, -K, ...)``); a target computes the sections' output and
applies its negative.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import control as ct
import numpy as np
from scipy import signal
from scipy.linalg import eigvals

from fsmbench import __version__
from fsmbench.control.seed import SEED_TS_S, tustin
from fsmbench.io.atomic import atomic_write_text
from fsmbench.io.matwrite import save_mat

__all__ = [
    "SOS_FORMAT",
    "siso_zpk",
    "sos_document",
    "sos_response",
    "state_space_struct",
    "tustin_sos",
    "write_controllers_mat",
    "write_sos_json",
]

SOS_FORMAT = "fsmbench-sos/1"


def state_space_struct(sys: ct.StateSpace, *, description: str = "") -> dict[str, Any]:
    """MATLAB struct fields of a state-space model: ``A, B, C, D, InputName, OutputName, Ts``.

    ``Ts`` is 0 for a continuous model (MATLAB's convention).
    """
    dt = sys.dt
    ts = 0.0 if dt in (None, 0) or dt is True else float(dt)
    return {
        "A": np.atleast_2d(np.asarray(sys.A, dtype=float)),
        "B": np.atleast_2d(np.asarray(sys.B, dtype=float)),
        "C": np.atleast_2d(np.asarray(sys.C, dtype=float)),
        "D": np.atleast_2d(np.asarray(sys.D, dtype=float)),
        "InputName": [str(x) for x in sys.input_labels],
        "OutputName": [str(x) for x in sys.output_labels],
        "Ts": ts,
        "Description": description,
    }


def write_controllers_mat(path: str | Path, controllers: Mapping[str, ct.StateSpace], *,
                          ts_s: float = SEED_TS_S,
                          descriptions: Mapping[str, str] | None = None) -> Path:
    """Write ``controllers.mat``: per controller a struct ``{K, Kd}``, plus ``fsmbench`` meta.

    Parameters
    ----------
    path : str or Path
        Destination (written atomically).
    controllers : mapping of name to control.StateSpace
        Continuous controllers; names must be MATLAB identifiers.
    ts_s : float
        Tustin sample time of ``Kd`` [s].
    descriptions : mapping of name to str, optional
    """
    desc = dict(descriptions or {})
    variables: dict[str, Any] = {}
    for name, k in controllers.items():
        text = desc.get(name, "")
        variables[name] = {"K": state_space_struct(k, description=text),
                           "Kd": state_space_struct(tustin(k, ts_s=ts_s), description=text)}
    variables["fsmbench"] = {"version": __version__, "Ts": float(ts_s),
                             "discretisation": "tustin (bilinear), no prewarping",
                             "feedback": "u = -K y",
                             "controllers": list(controllers)}
    return save_mat(path, variables)


def siso_zpk(sys: ct.StateSpace, *, output: int = 0,
             input: int = 0) -> tuple[np.ndarray, np.ndarray, float]:
    """Zeros, poles [rad/s] and leading coefficient of one channel of a continuous model.

    The channel keeps only the states structurally reachable from its input
    and observable from its output (exact for block-diagonal controllers such
    as ``control.append`` of SISO cascades, with no numerical cancellation).
    Zeros are the finite generalised eigenvalues of its system pencil; roots
    within 1e-7 of the largest root's modulus from the origin are set to 0
    (integrators); the gain is matched at one point away from every root.
    """
    a_full = np.asarray(sys.A, dtype=float)
    keep = _structural_states(a_full, np.asarray(sys.B, dtype=float)[:, input],
                              np.asarray(sys.C, dtype=float)[output, :])
    a = a_full[np.ix_(keep, keep)]
    b = np.asarray(sys.B, dtype=float)[keep][:, [input]]
    c = np.asarray(sys.C, dtype=float)[[output]][:, keep]
    d = np.asarray(sys.D, dtype=float)[[output]][:, [input]]
    n = a.shape[0]
    if n == 0:
        return np.zeros(0, dtype=complex), np.zeros(0, dtype=complex), float(d[0, 0])
    poles = np.linalg.eigvals(a).astype(complex)
    pencil = np.block([[a, b], [c, d]])
    e = np.zeros_like(pencil)
    e[:n, :n] = np.eye(n)
    z = eigvals(pencil, e)
    zeros = z[np.isfinite(z) & (np.abs(z) < 1e12)].astype(complex)
    scale = float(np.max(np.abs(np.concatenate([poles, zeros, [1.0]]))))
    poles[np.abs(poles) < 1e-7 * scale] = 0.0
    zeros[np.abs(zeros) < 1e-7 * scale] = 0.0
    s0 = 1j * 1.2345 * scale
    val = complex((c @ np.linalg.solve(s0 * np.eye(n) - a, b) + d)[0, 0])
    k = val * np.prod(s0 - poles) / np.prod(s0 - zeros)
    if abs(k.imag) > 1e-6 * abs(k):
        raise ValueError(f"channel gain is not real: {k}")
    return zeros, poles, float(k.real)


def _structural_states(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> list[int]:
    """States reachable from ``b`` and observable from ``c`` on the sparsity graph of ``a``."""
    nz = a != 0

    def closure(start: np.ndarray, adj: np.ndarray) -> np.ndarray:
        seen = start.copy()
        frontier = start.copy()
        while frontier.any():
            new = adj[:, frontier].any(axis=1) & ~seen
            seen |= new
            frontier = new
        return seen

    reach = closure(b != 0, nz)        # x_i driven by x_j when a[i, j] != 0
    observe = closure(c != 0, nz.T)    # x_j seen through x_i when a[i, j] != 0
    return [int(i) for i in np.nonzero(reach & observe)[0]]


def tustin_sos(sys: ct.StateSpace, *, ts_s: float = SEED_TS_S, output: int = 0,
               input: int = 0) -> np.ndarray:
    """Second-order sections ``[b0, b1, b2, 1, a1, a2]`` of one Tustin-discretised channel.

    Returns
    -------
    array, shape (n_sections, 6)
        In ``z^-1``; the overall gain sits in the first section (scipy's convention).
    """
    z, p, k = siso_zpk(sys, output=output, input=input)
    zd, pd, kd = signal.bilinear_zpk(z, p, k, fs=1.0 / ts_s)
    return np.asarray(signal.zpk2sos(zd, pd, kd, pairing="nearest"), dtype=float)


def sos_document(controllers: Mapping[str, ct.StateSpace], *, ts_s: float = SEED_TS_S,
                 descriptions: Mapping[str, str] | None = None) -> dict[str, Any]:
    """JSON-ready SOS description of the diagonal channels of each controller.

    Off-diagonal channels must be zero (the controllers here are decentralised).
    """
    desc = dict(descriptions or {})
    out: dict[str, Any] = {
        "format": SOS_FORMAT, "fsmbench_version": __version__, "sample_time_s": float(ts_s),
        "discretisation": "tustin (bilinear), no prewarping",
        "section_layout": ["b0", "b1", "b2", "a0", "a1", "a2"],
        "difference_equation": "a0 y[k] = b0 x[k] + b1 x[k-1] + b2 x[k-2] - a1 y[k-1] - a2 y[k-2]",
        "feedback": "u = -K y: apply the negative of the cascade's output to the command",
        "controllers": {},
    }
    for name, k in controllers.items():
        _check_diagonal(k, name)
        chans = []
        for i, (inp, outp) in enumerate(zip(k.input_labels, k.output_labels, strict=True)):
            sos = tustin_sos(k, ts_s=ts_s, output=i, input=i)
            chans.append({"input": str(inp), "output": str(outp), "n_sections": len(sos),
                          "sos": [[float(x) for x in row] for row in sos]})
        out["controllers"][name] = {"description": desc.get(name, ""), "channels": chans}
    return out


def write_sos_json(path: str | Path, controllers: Mapping[str, ct.StateSpace], *,
                   ts_s: float = SEED_TS_S,
                   descriptions: Mapping[str, str] | None = None) -> Path:
    """Write :func:`sos_document` as JSON, atomically."""
    doc = sos_document(controllers, ts_s=ts_s, descriptions=descriptions)
    return atomic_write_text(path, json.dumps(doc, indent=1) + "\n")


def _check_diagonal(k: ct.StateSpace, name: str) -> None:
    n = min(k.ninputs, k.noutputs)
    f = np.array([1.0, 37.0, 400.0])
    s = 2j * np.pi * f
    a = np.asarray(k.A, dtype=float)
    b = np.asarray(k.B, dtype=float)
    c = np.asarray(k.C, dtype=float)
    d = np.asarray(k.D, dtype=float)
    for x in s:
        h = c @ np.linalg.solve(x * np.eye(a.shape[0]) - a, b) + d if a.size else d
        off = h - np.diag(np.diag(h[:n, :n]))
        if np.max(np.abs(off)) > 1e-12 * max(np.max(np.abs(h)), 1e-300):
            raise ValueError(f"controller {name!r} is not diagonal; SOS export needs SISO channels")


def sos_response(sos: Sequence[Sequence[float]], f_hz: np.ndarray, *,
                 ts_s: float = SEED_TS_S) -> np.ndarray:
    """Frequency response of a cascade of sections at ``f_hz`` (for checks), shape (n,)."""
    _, h = signal.sosfreqz(np.asarray(sos, dtype=float), worN=np.asarray(f_hz, dtype=float),
                           fs=1.0 / ts_s)
    return np.asarray(h)
