"""Identification (seed section 2): spectral estimates with MATLAB semantics,
FRFs with per-line uncertainty (periodic averaging, the local polynomial
method), calibrations, delays, vector fitting, modal estimation and the
pipeline that turns recordings into an identified plant."""

from fsmbench.ident.calibration import (
    CurrentAmplifierGain,
    QdCalibration,
    calibrate_qd,
)
from fsmbench.ident.current_amp import calibrate_current_amplifier
from fsmbench.ident.delay.bode import DelayEstimate, estimate_delay, remove_delay
from fsmbench.ident.fit.modal import ModalEstimate, ModeEstimate, estimate_modes
from fsmbench.ident.fit.vectfit import Mode, VectorFit, VectorFitOptions, vector_fit
from fsmbench.ident.frf.estimate import FrfEstimate, combine_estimates
from fsmbench.ident.frf.lpm import LpmOptions, local_polynomial_frf
from fsmbench.ident.frf.periodic import PeriodicOptions, detect_period, periodic_frf
from fsmbench.ident.frf.spectral import (
    FrequencyResponse,
    SpectrumResult,
    WelchOptions,
    combine_columns,
    cpsd,
    default_nfft,
    default_noverlap,
    effective_averages,
    hamming,
    hann,
    hanning,
    mscohere,
    pwelch,
    spectral_matrix,
    tfestimate,
)

__all__ = [
    "CurrentAmplifierGain",
    "DelayEstimate",
    "FrequencyResponse",
    "FrfEstimate",
    "LpmOptions",
    "ModalEstimate",
    "Mode",
    "ModeEstimate",
    "PeriodicOptions",
    "QdCalibration",
    "SpectrumResult",
    "VectorFit",
    "VectorFitOptions",
    "WelchOptions",
    "calibrate_current_amplifier",
    "calibrate_qd",
    "combine_columns",
    "combine_estimates",
    "cpsd",
    "default_nfft",
    "default_noverlap",
    "detect_period",
    "effective_averages",
    "estimate_delay",
    "estimate_modes",
    "hamming",
    "hann",
    "hanning",
    "local_polynomial_frf",
    "mscohere",
    "periodic_frf",
    "pwelch",
    "remove_delay",
    "spectral_matrix",
    "tfestimate",
    "vector_fit",
]
