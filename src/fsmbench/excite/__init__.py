"""Excitation design for identification: multisines, band-limited noise, chirps.

This ``__init__`` imports nothing (the command line registers ``excite``
without loading numpy's and scipy's heavier parts); import from the modules:

- :mod:`fsmbench.excite.design`: random-phase and crest-factor-minimised
  multisines (full, odd, odd-odd, linear or log grids), band-limited noise as
  the ESRF study injects it, chirps;
- :mod:`fsmbench.excite.limits`: the peak at the DAC and at every ADC channel
  the bench model carries the excitation to, and the 4QD's compression at the
  beam's peak, checked before anything is written;
- :mod:`fsmbench.excite.mains`: multisine lines on mains harmonics, the grids
  that avoid them, the warning;
- :mod:`fsmbench.excite.files`: the MAT-file a real-time target plays and its
  JSON description (``fsmbench.excitation`` version 1), written and read back;
- :mod:`fsmbench.cli.commands.excite`: ``fsmbench excite``.

``fsmbench simulate --excitation FILE`` plays a file on the twin
(:func:`fsmbench.twin.simulate.simulate_excitation`).
"""

__all__ = ["cli", "design", "files", "limits", "mains"]
