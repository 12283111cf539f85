"""The statistics of the results tables: a mean's percentile bootstrap interval, a rate's Wilson score interval.

Both are deterministic (the bootstrap resamples with a fixed seed), so a table regenerates with the same bits.
"""

from __future__ import annotations

import math

import numpy as np

BOOTSTRAP_RESAMPLES = 10_000
BOOTSTRAP_SEED = 0
CONFIDENCE = 0.95
WILSON_Z = 1.959963984540054  # standard normal quantile of 0.975


def bootstrap_mean(values: np.ndarray) -> tuple[float, float, float]:
    """Mean and its 95 % percentile bootstrap interval (BOOTSTRAP_RESAMPLES resamples, fixed seed)."""
    values = np.asarray(values, dtype=float)
    rng = np.random.default_rng(BOOTSTRAP_SEED)
    means = values[rng.integers(0, values.size, size=(BOOTSTRAP_RESAMPLES, values.size))].mean(axis=1)
    low, high = np.quantile(means, [(1 - CONFIDENCE) / 2, (1 + CONFIDENCE) / 2])
    return float(values.mean()), float(low), float(high)


def wilson_interval(successes: int, trials: int) -> tuple[float, float, float]:
    """Rate and its 95 % Wilson score interval."""
    rate, z2 = successes / trials, WILSON_Z**2
    centre = (rate + z2 / (2 * trials)) / (1 + z2 / trials)
    half = WILSON_Z * math.sqrt(rate * (1 - rate) / trials + z2 / (4 * trials**2)) / (1 + z2 / trials)
    return rate, max(0.0, centre - half), min(1.0, centre + half)


def oracle_share(policy: np.ndarray, blind: np.ndarray, oracle: np.ndarray) -> tuple[float, float, float]:
    """The share of the oracle gap captured, mean(policy - blind) / mean(oracle - blind), with its 95 % paired
    bootstrap interval (the episodes resampled together); NaN where the oracle does not beat the blind constant."""
    gained, gap = np.asarray(policy) - np.asarray(blind), np.asarray(oracle) - np.asarray(blind)
    if gap.mean() <= 0:
        return math.nan, math.nan, math.nan
    rng = np.random.default_rng(BOOTSTRAP_SEED)
    index = rng.integers(0, gap.size, size=(BOOTSTRAP_RESAMPLES, gap.size))
    resampled_gap = gap[index].mean(axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        shares = np.where(resampled_gap > 0, gained[index].mean(axis=1) / resampled_gap, np.nan)
    if np.isnan(shares).any():  # a resample where the oracle gains nothing: no interval
        return float(gained.mean() / gap.mean()), math.nan, math.nan
    low, high = np.quantile(shares, [(1 - CONFIDENCE) / 2, (1 + CONFIDENCE) / 2])
    return float(gained.mean() / gap.mean()), float(low), float(high)


__all__ = ["BOOTSTRAP_RESAMPLES", "BOOTSTRAP_SEED", "CONFIDENCE", "WILSON_Z", "bootstrap_mean", "oracle_share",
           "wilson_interval"]
