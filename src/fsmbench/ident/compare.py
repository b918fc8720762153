"""The identified model against each identification record, with its NRMSE fit (MATLAB's
``compare``).

The identified plant (:attr:`fsmbench.ident.result.Identification.plant`) is sampled as
a minimal discrete model with its delays exact
(:meth:`fsmbench.bench.blocks.PlantModel.to_control` with ``delays="exact"``, a zero-order
hold at the records' rate), driven from rest by the recorded command of each open-loop
identification record, and its outputs compared with the recorded ones:

    fit = 100 (1 − ‖y − ŷ‖ / ‖y − mean(y)‖)   [%]

per output, MATLAB's normalised root-mean-square fit (100 % is perfect, 0 % no better
than the mean). As MATLAB's ``compare`` does with detrended data, every record's mean
is removed (the command's before simulating, each output's and the model's over the
compared span: offsets and the 4QD's DC are not the model's business). The model starts
at rest while the bench was already moving, so the first ``settle_s`` seconds (at
least the identification's own trim of that record) are left out.

A perfect model with white noise of variance σn² on an output of variance σy² (noise
included) fits at most ``100 (1 − sqrt(σn²/σy²))`` %: the cross paths, where the
Sercalo's coupling is small, fit less for that reason alone.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import xarray as xr

from fsmbench.bench.blocks import PlantModel

__all__ = ["RECORDS", "ModelComparison", "RecordFit", "compare_records", "lifted_response",
           "nrmse_fit_percent"]

#: The open-loop identification records the study uses: (experiment, input, outputs).
RECORDS: tuple[tuple[str, str, tuple[str, ...]], ...] = (
    ("data_uch", "Uch", ("Vph", "Vpv", "Vch", "Vcv")),
    ("data_ucv", "Ucv", ("Vph", "Vpv", "Vch", "Vcv")),
    ("data_unh", "Unh", ("Vph", "Vpv")),
    ("data_unv", "Unv", ("Vph", "Vpv")),
)


def nrmse_fit_percent(y: np.ndarray, y_model: np.ndarray) -> float:
    """MATLAB's NRMSE fit ``100 (1 − ‖y − ŷ‖ / ‖y − mean(y)‖)`` [%] (NaN for a constant ``y``)."""
    y = np.asarray(y, dtype=float).ravel()
    y_model = np.asarray(y_model, dtype=float).ravel()
    if y.shape != y_model.shape:
        raise ValueError(f"y has {y.size} samples, the model {y_model.size}")
    scale = float(np.linalg.norm(y - y.mean()))
    if scale == 0.0:
        return float("nan")
    return 100.0 * (1.0 - float(np.linalg.norm(y - y_model)) / scale)


@dataclass(frozen=True, eq=False)
class RecordFit:
    """One output of one record against the model.

    Attributes
    ----------
    experiment, input, output : str
        The record (``"data_uch"``), its command (``"Uch"``) and the output (``"Vph"``).
    fit_percent : float
        NRMSE fit over the compared span [%].
    compared_from_s : float
        Start of the compared span from the record's start [s] (the rest is to its end).
    t_s, y_v, y_model_v : numpy.ndarray
        A short window from the compared span's start, every sample: time from the
        record's start [s], the recorded output and the model's, each less its mean
        over the compared span [V].
    """

    experiment: str
    input: str
    output: str
    fit_percent: float
    compared_from_s: float
    t_s: np.ndarray
    y_v: np.ndarray
    y_model_v: np.ndarray

    def to_json(self) -> dict[str, Any]:
        """The numbers, not the window."""
        return {"experiment": self.experiment, "input": self.input, "output": self.output,
                "fit_percent": float(self.fit_percent),
                "compared_from_s": float(self.compared_from_s)}


@dataclass(frozen=True, eq=False)
class ModelComparison:
    """The identified model against every open-loop identification record.

    Attributes
    ----------
    fits : tuple of RecordFit
        Per record and output, in :data:`RECORDS`' order.
    settle_s : float
        Seconds the model is given to settle from rest before comparing [s].
    window_s : float
        Length of each stored window [s].
    skipped : mapping experiment -> reason
        Records not compared (absent, or the command or an output missing).
    """

    fits: tuple[RecordFit, ...]
    settle_s: float
    window_s: float
    skipped: Mapping[str, str]

    def fit_percent(self, experiment: str, output: str) -> float:
        """The fit of ``output`` on ``experiment`` [%] (NaN when not compared)."""
        for f in self.fits:
            if f.experiment == experiment and f.output == output:
                return f.fit_percent
        return float("nan")

    def to_json(self) -> dict[str, Any]:
        """Plain values."""
        return {"settle_s": float(self.settle_s), "window_s": float(self.window_s),
                "fits": [f.to_json() for f in self.fits], "skipped": dict(self.skipped)}


def lifted_response(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray,
                    u: np.ndarray, *, block: int = 256) -> np.ndarray:
    """Outputs (N, p) from rest of ``x⁺ = A x + B u``, ``y = C x + D u`` (one input).

    The same recursion as ``scipy.signal.dlsim``, in blocks of ``block`` samples: the
    state only at the blocks' starts, the samples in between as matrix products with the
    Markov parameters (a lifted system), so that a record of 10⁵ samples takes
    milliseconds, not a Python loop per sample.
    """
    u = np.asarray(u, dtype=float).ravel()
    n_samples, n = u.size, a.shape[0]
    p = c.shape[0]
    if n == 0:
        return np.outer(u, d[:, 0])
    n_blocks = -(-n_samples // block)
    padded = np.zeros(n_blocks * block)
    padded[:n_samples] = u
    ub = padded.reshape(n_blocks, block)
    # A^j for j = 0 … block: the free response C A^j and the Markov parameters C A^j B.
    powers = np.empty((block + 1, n, n))
    powers[0] = np.eye(n)
    for j in range(1, block + 1):
        powers[j] = a @ powers[j - 1]
    free = np.einsum("pn,jnm->jpm", c, powers[:block])  # (block, p, n)
    markov = free @ b[:, 0]  # (block, p): C A^j B
    # Within a block: y[i] = D u[i] + Σ_{k<i} C A^{i-1-k} B u[k].
    lag = np.arange(block)[None, :] - np.arange(block)[:, None] - 1  # i - k - 1, as [k, i]
    toeplitz = np.where(lag[..., None] >= 0, markov[np.clip(lag, 0, None)], 0.0)
    toeplitz[np.arange(block), np.arange(block)] = d[:, 0]
    y = np.einsum("bk,kip->bip", ub, toeplitz)
    # The state at each block's start: x_{b+1} = A^L x_b + Σ_k A^{L-1-k} B u[k].
    drive = ub @ np.einsum("knm,m->kn", powers[block - 1::-1], b[:, 0])  # (n_blocks, n)
    states = np.zeros((n_blocks, n))
    for k in range(1, n_blocks):
        states[k] = powers[block] @ states[k - 1] + drive[k - 1]
    y += np.einsum("bn,ipn->bip", states, free)
    return y.reshape(n_blocks * block, p)[:n_samples]


def _simulate(plant: PlantModel, *, input_name: str, outputs: Sequence[str], u: np.ndarray,
              ts_s: float) -> np.ndarray:
    """The sampled model's outputs (N, len(outputs)) from rest for the held command ``u``."""
    sys = plant.to_control(delays="exact", dt=ts_s, inputs=[input_name], outputs=list(outputs))
    a, b, c, d = (np.asarray(x, dtype=float) for x in (sys.A, sys.B, sys.C, sys.D))
    return lifted_response(a, b, c, d, u)


def compare_records(recordings: Mapping[str, xr.Dataset], *, plant: PlantModel,
                    trims_s: Mapping[str, float] | None = None, settle_s: float = 1.0,
                    window_s: float = 0.05,
                    records: Sequence[tuple[str, str, Sequence[str]]] = RECORDS
                    ) -> ModelComparison:
    """The model's response to each record's command against the recorded outputs.

    Parameters
    ----------
    recordings : mapping experiment -> Dataset
        As :func:`fsmbench.ident.pipeline.identify` takes them (``t`` and the signals).
    plant : PlantModel
        The model to compare (the identified one).
    trims_s : mapping experiment -> seconds, optional
        The identification's trims: the compared span starts at the later of the trim
        and ``settle_s``.
    settle_s : float
        Seconds from rest the model is given before comparing [s].
    window_s : float
        Length of the window kept for drawing [s].
    records : sequence of (experiment, input, outputs)
        Default :data:`RECORDS`.
    """
    trims = dict(trims_s or {})
    fits: list[RecordFit] = []
    skipped: dict[str, str] = {}
    for experiment, input_name, outs in records:
        ds = recordings.get(experiment)
        if ds is None:
            skipped[experiment] = "not in the data"
            continue
        present = [o for o in outs if o in ds.data_vars]
        if input_name not in ds.data_vars or not present:
            skipped[experiment] = f"no {input_name} or none of {', '.join(outs)} recorded"
            continue
        fs_hz = float(ds.attrs.get("fs_hz", 0.0)) or 1.0 / float(np.median(np.diff(ds["t"])))
        ts_s = 1.0 / fs_hz
        u = np.asarray(ds[input_name].values, dtype=float)
        t = np.asarray(ds["t"].values, dtype=float) if "t" in ds else np.arange(u.size) * ts_s
        t = t - t[0]
        start = int(np.ceil(max(settle_s, trims.get(experiment, 0.0)) * fs_hz))
        if start >= u.size - 2 or not np.all(np.isfinite(u)):
            skipped[experiment] = ("shorter than the settling interval" if start >= u.size - 2
                                   else f"{input_name} not finite")
            continue
        y_model = _simulate(plant, input_name=input_name, outputs=present, u=u - u.mean(),
                            ts_s=ts_s)
        n_win = max(2, round(window_s * fs_hz))
        for j, name in enumerate(present):
            y = np.asarray(ds[name].values, dtype=float)[start:]
            ym = y_model[start:, j]
            if not np.all(np.isfinite(y)):
                skipped[f"{experiment}.{name}"] = f"{name} not finite"
                continue
            y = y - y.mean()
            ym = ym - ym.mean()
            fits.append(RecordFit(
                experiment=experiment, input=input_name, output=name,
                fit_percent=nrmse_fit_percent(y, ym), compared_from_s=float(t[start]),
                t_s=t[start:start + n_win].copy(), y_v=y[:n_win].copy(),
                y_model_v=ym[:n_win].copy()))
    return ModelComparison(fits=tuple(fits), settle_s=float(settle_s), window_s=float(window_s),
                           skipped=skipped)
