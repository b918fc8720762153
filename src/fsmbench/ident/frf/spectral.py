"""Welch spectral estimation with MATLAB's semantics, and one-pass FRF matrices.

The seed study (sections 2.2-2.4, 3.5) calls ``tfestimate``, ``mscohere`` and
``pwelch`` with ``win = hanning(ceil(1*fs))``, ``[]`` overlap and nfft, and
``fs = 1e4``. This module gives a MATLAB user the same numbers for the same
arguments, and computes a whole experiment (all inputs and outputs) in one
pass. Implementation: :mod:`fsmbench.signal.welch` (windows, options, engine,
SISO functions) and :mod:`fsmbench.ident.frf.response` (FRF matrix, bounds).

Conventions (each checked against the source named; URLs as retrieved)
----------------------------------------------------------------------
Windows
    ``hanning(n) = 0.5*(1 - cos(2*pi*k/(n+1)))``, ``k = 1..n``: symmetric, no
    zero end-points; ``hann(n)`` uses ``k/(n-1)``, ``k = 0..n-1`` (zero ends,
    equal to ``scipy.signal.windows.hann(n, sym=True)``). MATLAB Answers 41903
    "hanning window" (``hanning(5) = [.25 .75 1 .75 .25]``, ``hann(5) = [0 .5 1 .5 0]``),
    https://ww2.mathworks.cn/matlabcentral/answers/41903-hanning-window.
    Both are built as a half window mirrored, as MATLAB does.
Integer ``window``
    "If window is an integer, the signal is divided into segments of length
    window ... using a Hamming window of length window" (MathWorks ``pwelch``
    page, https://mathworks.com/help/signal/ref/pwelch.html); ``hamming(L)`` is
    symmetric by default (https://uk.mathworks.com/help/signal/ref/hamming.html).
``noverlap = []``
    50 % overlap, ``floor(L/2)`` samples (pwelch page; MathWorks Support answer
    434104: 3244-sample segments overlap by 1622).
``nfft = []``
    ``max(256, 2^nextpow2(L))`` ("256 or the next power of two greater than the
    length of each section ... whichever is larger", MathWorks answer 434104,
    https://uk.mathworks.com/matlabcentral/answers/434104). ``hanning(10000)`` -> 16384.
Segments
    ``K = floor((N - noverlap)/(L - noverlap))``, trailing samples dropped
    (answer 434104: 14600 samples -> 8 segments; J. O. Smith, *Spectral Audio
    Signal Processing*, eq. 7.28, https://ccrma.stanford.edu/~jos/sasp/).
``nfft < L``
    each windowed segment is wrapped (summed modulo nfft) to nfft samples, as
    MATLAB's ``datawrap`` ("If nfft is less than the signal length, the segment
    is wrapped so that the length is equal to nfft", cpsd/tfestimate reference
    pages, older releases). scipy refuses this case.
Scaling and grid
    density ``|X|^2 / (fs * sum(w^2))`` averaged over segments; one-sided for
    real input on ``(0:floor(nfft/2)) * fs/nfft`` (length ``nfft/2+1`` even,
    ``(nfft+1)/2`` odd, cpsd/tfestimate pages), doubled except DC and (even nfft)
    Nyquist - identical to ``scipy.signal.welch(..., scaling='density')``, against
    which the tests check it to 1e-10.
No detrending
    MATLAB's pwelch/cpsd/tfestimate/mscohere have no detrend option (dropped
    with ``psd``'s ``dflag``, MATLAB Answers "Can I specify the detrending option
    in the PWELCH function", matlabsolutions.com mirror) and a DC offset shows in
    ``pwelch`` output (MATLAB Answers "No obvious maximum in power spectral
    density graph", imathworks.com mirror). One community answer (Answers
    1616345) claims pwelch detrends; MathWorks' pages describe no such step, so
    none is done. scipy's default is ``detrend='constant'`` (scipy.signal.csd docs);
    pass ``detrend=False`` to compare.
``cpsd(x, y)``
    MATLAB averages ``X conj(Y)`` (its documented ``R_xy(m) = E{x[n+m] y*[n]}``);
    MathWorks staff, Answers 417050: "in tfestimate, the transfer function is
    defined as Pyx/Pxx, and Pyx is conjugate of Pxy, that's why you see the sign
    difference in angle" when dividing ``cpsd(x,y)`` by ``Pxx``
    (https://nl.mathworks.com/matlabcentral/answers/417050). scipy's
    ``csd(x, y)`` averages ``conj(X) Y`` (``np.conjugate(result) * result_y``,
    scipy PR #4682), so MATLAB ``cpsd(x, y) = conj(scipy csd(x, y))``.
``tfestimate``
    default estimator H1, ``Txy = Pyx/Pxx`` (MathWorks tfestimate page,
    https://uk.mathworks.com/help/signal/ref/tfestimate.html), i.e. average of
    ``Y conj(X)`` over average of ``|X|^2`` = Bendat & Piersol's ``G_xy/G_xx`` with
    ``G_xy = E[X* Y]`` (B&P 4th ed., eq. 9.1). A delay of d samples gives phase
    ``-2 pi f d / fs`` (tested).
``mscohere``
    ``|Pxy|^2 / (Pxx Pyy)`` (scipy.signal.coherence docs; MathWorks mscohere page:
    "You must use at least two segments. Otherwise, the magnitude-squared
    coherence is 1 for all frequencies" - fewer than two segments raise here).
Effective averages ``n_d``
    Welch, P. D. (1967), IEEE Trans. Audio Electroacoust. AU-15(2):70-73:
    ``Var/P^2 = (1/K)[1 + 2 sum_j (1 - j/K) rho(j)^2]`` with ``rho(j)`` the
    window's overlap correlation at ``j`` hops (definition: "Overlap correlation",
    https://www.recordingblogs.com/wiki/overlap-correlation; Hann at 50 %:
    rho = 0.167, Harris 1978). ``n_d = K / [...]``. The tests check the implied
    variance on simulated white noise at 75 % overlap, where ``n_d ~ K/1.9``.
Confidence bounds
    Bendat & Piersol, *Random Data*, ch. 9 (gain and phase of FRF estimates):
    ``eps = sqrt(1 - g^2) / (|g| sqrt(2 n_d))`` is the normalised random error of
    ``|H|`` and the standard deviation of the phase in rad (as quoted from B&P
    2nd ed. p. 317 in LIGO aLOG 10506, https://alog.ligo-wa.caltech.edu/aLOG/,
    report 10506). Bounds use the Gaussian approximation B&P give for small
    errors: ``|H| (1 -/+ z eps)`` (lower clipped at 0) and ``angle(H) -/+ z eps``,
    ``z`` the two-sided normal quantile of ``confidence``. For ``m > 1`` inputs,
    ``Var(H_ki) = Gnn_k [Sxx^-1]_ii / (n_d - m + 1)``, ``Gnn`` the residual output
    spectrum: it reduces to the formula above for ``m = 1``; the ``m - 1`` lost
    degrees of freedom follow the multiple-input treatment (B&P ch. 9; Goodman,
    AFFDL-TR-65-56, 1965) - not checked against B&P's printed equation, but the
    tests check the coverage of both cases on simulated data.
"""

from __future__ import annotations

from fsmbench.ident.frf.response import FrequencyResponse, combine_columns, spectral_matrix
from fsmbench.signal.welch import (
    SpectrumResult,
    WelchOptions,
    cpsd,
    default_nfft,
    default_noverlap,
    effective_averages,
    hamming,
    hann,
    hanning,
    mscohere,
    pwelch,
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
