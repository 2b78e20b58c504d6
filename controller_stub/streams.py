"""The stub's seeded random streams.

Every random feature draws from its own stream of the scenario's seed, so adding draws to one
feature never changes another.
"""

from __future__ import annotations

import numpy as np

# Independent random streams (so adding draws to one feature never changes another).
STREAM_TRUTH, STREAM_VIEWS, STREAM_PROBE, STREAM_LEFT, STREAM_RIGHT = range(1, 6)


def stream_rng(seed: int, stream: int) -> np.random.Generator:
    """The generator of random stream `stream` (1, 2, ...) of the scenario seed `seed`."""
    return np.random.default_rng([int(seed) & 0xFFFFFFFF, stream])
