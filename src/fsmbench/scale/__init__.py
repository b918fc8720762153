"""Long records out of core and runs on a cluster (Dask).

The modules of this package import :mod:`dask` (the ``fsmbench[dask]`` extra);
this ``__init__`` imports nothing, so ``import fsmbench`` works without Dask.
Import the functions from their modules:

- :mod:`fsmbench.signal.welch_dask`: Welch PSD/CPSD/H1/coherence on Dask arrays,
  MATLAB semantics, equal to :mod:`fsmbench.signal.welch`;
- :mod:`fsmbench.signal.allan`: overlapping Allan deviation of long records and
  its noise-type slope regions;
- :mod:`fsmbench.signal.envelope`: min/max/mean envelope of long records for plots.
"""

__all__ = ["allan", "envelope", "welch"]
