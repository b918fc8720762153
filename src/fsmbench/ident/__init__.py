"""Identification: spectral estimates (MATLAB semantics) and FRF matrices."""

from fsmbench.ident.spectral import (
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
    "FrequencyResponse",
    "SpectrumResult",
    "WelchOptions",
    "combine_columns",
    "cpsd",
    "default_nfft",
    "default_noverlap",
    "effective_averages",
    "hamming",
    "hann",
    "hanning",
    "mscohere",
    "pwelch",
    "spectral_matrix",
    "tfestimate",
]
