"""Delays and lags: the Bode-phase delay, the joint delay fit, the Sercalo's delay with its
sensor, sampled paths.
"""

__all__: list[str] = []
