"""Signal estimates with MATLAB's semantics, one function per estimator for NumPy and Dask
arrays: Welch's PSD, CPSD, transfer function and coherence (:mod:`fsmbench.signal.welch`),
their engine (:mod:`fsmbench.signal.welch_core`), its Dask graph
(:mod:`fsmbench.signal.welch_dask`, the ``dask`` extra) and the segment sums both use
(:mod:`fsmbench.signal.segments`). A building block of every stage: it imports no stage.
"""
