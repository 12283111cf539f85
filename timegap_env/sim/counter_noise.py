"""Counter-based random numbers: a uniform is a hash of a key and a counter, no generator state.

A draw depends only on its key (one per env and episode) and its counter (built from the tick
since reset, the follower and a stream), never on which other envs share a batch or how ticks
are grouped into blocks, so a vector of envs reproduces the same envs run one by one. The
physics (V2V packet loss) and the sensors (noise, dropouts) draw this way, each from its own key.
"""

from __future__ import annotations

import numba
import numpy as np

from timegap_env.compiled import follow_sources

_SPLITMIX_INCREMENT = np.uint64(0x9E3779B97F4A7C15)  # SplitMix64 constants (Steele, Lea & Flood 2014)
_SPLITMIX_MULTIPLIERS = (np.uint64(0xBF58476D1CE4E5B9), np.uint64(0x94D049BB133111EB))


@numba.njit(cache=True, error_model="numpy")
def counter_uniform(key, counter):  # noqa: ANN001, ANN201
    """The uniform in (0, 1) of the uint64 ``counter`` under the uint64 ``key``."""
    bits = _splitmix64(_splitmix64(counter * _SPLITMIX_INCREMENT + key))
    return (float(bits >> np.uint64(11)) + 0.5) * 2.0**-53


@numba.njit(cache=True, error_model="numpy")
def _splitmix64(x):  # noqa: ANN001, ANN202
    """SplitMix64 finaliser: a well-mixed uint64 hash of the uint64 ``x``."""
    x = (x ^ (x >> np.uint64(30))) * _SPLITMIX_MULTIPLIERS[0]
    x = (x ^ (x >> np.uint64(27))) * _SPLITMIX_MULTIPLIERS[1]
    return x ^ (x >> np.uint64(31))


follow_sources(__name__)
