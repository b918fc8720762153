"""Plant analysis, controllers (the seed's and fsmbench's), discretisation and export."""

from fsmbench.control.realize import zpk_cascade
from fsmbench.control.seed import (
    iff_controller,
    newport_controller,
    seed_decentralised_controller,
    tustin,
)

__all__ = [
    "iff_controller",
    "newport_controller",
    "seed_decentralised_controller",
    "tustin",
    "zpk_cascade",
]
