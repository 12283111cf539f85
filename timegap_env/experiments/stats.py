"""The statistics of the results tables: a mean's percentile bootstrap interval, a rate's Wilson score interval, the
power of a paired comparison, and the aggregates over training runs and tasks of Agarwal et al. (2021), "Deep RL at
the Edge of the Statistical Precipice": the interquartile mean, the stratified bootstrap, the probability of
improvement and the performance profile.

All are deterministic (the bootstraps resample with a fixed seed), so a table regenerates with the same bits.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

BOOTSTRAP_RESAMPLES = 10_000
BOOTSTRAP_SEED = 0
CONFIDENCE = 0.95
WILSON_Z = 1.959963984540054  # standard normal quantile of 0.975
POWER = 0.8
POWER_Z = 0.8416212335729143  # standard normal quantile of POWER


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


def _power_z(power: float) -> float:
    """The standard normal quantile of power (POWER_Z for the default, else scipy's ndtri, imported on demand)."""
    if not 0 < power < 1:
        raise ValueError(f"power must lie in (0, 1), not {power}")
    if power == POWER:
        return POWER_Z
    from scipy.special import ndtri

    return float(ndtri(power))


def paired_mde(differences: np.ndarray, power: float = POWER) -> float:
    """The minimum detectable effect of a paired mean difference (units of the differences) at 95 % two-sided
    confidence and the given power: (z_0.975 + z_power) * sd(differences, ddof=1) / sqrt(n)."""
    differences = np.asarray(differences, dtype=float).ravel()
    if differences.size < 2:
        raise ValueError(f"paired_mde needs at least 2 differences, not {differences.size}")
    sd = float(differences.std(ddof=1))
    return (WILSON_Z + _power_z(power)) * sd / math.sqrt(differences.size)


def episodes_for(sd: float, effect: float, power: float = POWER) -> int:
    """The number of paired episodes at which a mean difference of effect (units of sd) is detectable at 95 %
    two-sided confidence and the given power: ceil(((z_0.975 + z_power) * sd / effect)^2), at least 2."""
    if effect <= 0 or sd < 0:
        raise ValueError(f"episodes_for needs effect > 0 and sd >= 0, not effect={effect}, sd={sd}")
    required = ((WILSON_Z + _power_z(power)) * sd / effect) ** 2
    return max(2, math.ceil(required * (1 - 1e-12)))  # the tolerance: paired_mde's own effect gives back its n


def _runs_by_tasks(scores: np.ndarray, name: str = "scores") -> np.ndarray:
    """scores as a float (n_runs, n_tasks) array, checked: two dimensions, not empty, no NaN."""
    scores = np.asarray(scores, dtype=float)
    if scores.ndim != 2 or scores.size == 0:
        raise ValueError(f"{name} must be a non-empty (n_runs, n_tasks) array, not of shape {scores.shape}")
    if np.isnan(scores).any():
        raise ValueError(f"{name} contain NaN")
    return scores


def _iqm_rows(rows: np.ndarray) -> np.ndarray:
    """The interquartile mean of each row of a 2-D array (scipy.stats.trim_mean(row, 0.25) semantic)."""
    cut = int(0.25 * rows.shape[1])
    return np.sort(rows, axis=1)[:, cut : rows.shape[1] - cut].mean(axis=1)


def iqm(scores: np.ndarray) -> float:
    """The interquartile mean of all values of scores (flattened; units of scores): the mean of the middle 50 %, a
    quarter of the values cut from each end (rounded down, as scipy.stats.trim_mean(scores, 0.25, axis=None))."""
    values = np.asarray(scores, dtype=float).reshape(1, -1)
    if values.size == 0 or np.isnan(values).any():
        raise ValueError("iqm needs a non-empty array without NaN")
    return float(_iqm_rows(values)[0])


def _resample_index(rng: np.random.Generator, n_runs: int, n_tasks: int, resamples: int) -> np.ndarray:
    """Stratified resampling indices, (resamples, n_runs, n_tasks): each task's runs drawn with replacement from
    that task's column, independently of the other tasks."""
    return rng.integers(0, n_runs, size=(resamples, n_runs, n_tasks))


def _run_counts(index: np.ndarray, n_runs: int) -> np.ndarray:
    """How often each run of each task is drawn in each resample, (resamples, n_runs, n_tasks), from the indices
    of _resample_index."""
    resamples, _, n_tasks = index.shape
    flat = (np.arange(resamples)[:, None, None] * n_runs + index) * n_tasks + np.arange(n_tasks)
    return np.bincount(flat.ravel(), minlength=resamples * n_runs * n_tasks).reshape(resamples, n_runs, n_tasks)


def _interval(point: float, resampled: np.ndarray) -> tuple[float, float, float]:
    """point and the 95 % percentile interval of its resampled values."""
    low, high = np.quantile(resampled, [(1 - CONFIDENCE) / 2, (1 + CONFIDENCE) / 2])
    return point, float(low), float(high)


# Statistics with a vectorised path: (resamples, n_runs, n_tasks) -> (resamples,), the same values as the statistic
# applied to each resample in turn.
_BATCHED: dict[Callable[[np.ndarray], float], Callable[[np.ndarray], np.ndarray]] = {
    iqm: lambda resampled: _iqm_rows(resampled.reshape(resampled.shape[0], -1)),
}


def stratified_bootstrap(scores: np.ndarray, statistic: Callable[[np.ndarray], float],
                         resamples: int = BOOTSTRAP_RESAMPLES) -> tuple[float, float, float]:
    """statistic(scores) (units of the statistic) and its 95 % percentile stratified bootstrap interval; scores is
    (n_runs, n_tasks) (runs: training seeds; tasks: benchmark groups), and each resample draws n_runs runs with
    replacement within each task independently (fixed seed). statistic maps an (n_runs, n_tasks) array to a float;
    iqm has a vectorised path, any other statistic is applied to each resample in turn."""
    scores = _runs_by_tasks(scores)
    if resamples < 1:
        raise ValueError(f"resamples must be at least 1, not {resamples}")
    n_runs, n_tasks = scores.shape
    index = _resample_index(np.random.default_rng(BOOTSTRAP_SEED), n_runs, n_tasks, resamples)
    resampled = scores[index, np.arange(n_tasks)]
    batched = _BATCHED.get(statistic)
    if batched is not None:
        values = batched(resampled)
    else:
        values = np.array([statistic(sample) for sample in resampled], dtype=float)
    return _interval(float(statistic(scores)), values)


def _paired_outcomes(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Per run pair and task, 1 where x's run beats y's, 1/2 on a tie, else 0: (n_x_runs, n_y_runs, n_tasks)."""
    x, y = x[:, None, :], y[None, :, :]
    return (x > y) + 0.5 * (x == y)


def _improvement_inputs(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """x and y as checked (n_runs, n_tasks) float arrays over the same tasks."""
    x, y = _runs_by_tasks(x, "x"), _runs_by_tasks(y, "y")
    if x.shape[1] != y.shape[1]:
        raise ValueError(f"x and y must have the same tasks (columns), not {x.shape[1]} and {y.shape[1]}")
    return x, y


def probability_of_improvement(x: np.ndarray, y: np.ndarray) -> float:
    """The probability that a run of x beats a run of y on a task (in [0, 1]), averaged over tasks: per task, the
    Mann-Whitney U statistic over all run pairs (ties count 1/2) divided by the number of pairs. x is
    (n_x_runs, n_tasks), y (n_y_runs, n_tasks); a deterministic policy is a single run."""
    x, y = _improvement_inputs(x, y)
    return float(_paired_outcomes(x, y).mean(axis=(0, 1)).mean())


def probability_of_improvement_interval(x: np.ndarray, y: np.ndarray) -> tuple[float, float, float]:
    """probability_of_improvement(x, y) and its 95 % percentile stratified bootstrap interval: x's and y's runs
    resampled independently, each within each task (fixed seed)."""
    x, y = _improvement_inputs(x, y)
    n_tasks = x.shape[1]
    rng = np.random.default_rng(BOOTSTRAP_SEED)
    x_counts = _run_counts(_resample_index(rng, x.shape[0], n_tasks, BOOTSTRAP_RESAMPLES), x.shape[0]).astype(float)
    y_counts = _run_counts(_resample_index(rng, y.shape[0], n_tasks, BOOTSTRAP_RESAMPLES), y.shape[0]).astype(float)
    # A resample's wins on a task: the outcomes of the original pairs weighted by how often each run is drawn. The
    # sums are of halves of integers, exact in floats, so the summation order cannot change a bit.
    wins = np.einsum("rjt,rit,ijt->rt", y_counts, x_counts, _paired_outcomes(x, y))
    values = (wins / (x.shape[0] * y.shape[0])).mean(axis=1)
    return _interval(probability_of_improvement(x, y), values)


def performance_profile(scores: np.ndarray, thresholds: np.ndarray) -> np.ndarray:
    """The score distribution: the fraction (in [0, 1]) of all (run, task) scores strictly above each threshold
    (units of scores), shape (len(thresholds),)."""
    scores = _runs_by_tasks(scores)
    thresholds = np.asarray(thresholds, dtype=float).ravel()
    return (scores.reshape(-1, 1) > thresholds).mean(axis=0)


def performance_profile_interval(scores: np.ndarray,
                                 thresholds: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """performance_profile(scores, thresholds) and its pointwise 95 % percentile stratified bootstrap band (low,
    high), each of shape (len(thresholds),); scores is (n_runs, n_tasks), resampled within each task (fixed
    seed)."""
    scores = _runs_by_tasks(scores)
    thresholds = np.asarray(thresholds, dtype=float).ravel()
    n_runs, n_tasks = scores.shape
    counts = _run_counts(_resample_index(np.random.default_rng(BOOTSTRAP_SEED), n_runs, n_tasks, BOOTSTRAP_RESAMPLES),
                         n_runs)
    above = (scores[:, :, None] > thresholds).astype(float)  # (n_runs, n_tasks, n_thresholds)
    # A resample's count above each threshold: the original indicators weighted by how often each run is drawn
    # (integer sums, exact in floats, so the product's summation order cannot change a bit).
    resampled = counts.reshape(BOOTSTRAP_RESAMPLES, -1).astype(float) @ above.reshape(-1, thresholds.size) / scores.size
    low, high = np.quantile(resampled, [(1 - CONFIDENCE) / 2, (1 + CONFIDENCE) / 2], axis=0)
    return performance_profile(scores, thresholds), low, high


__all__ = ["BOOTSTRAP_RESAMPLES", "BOOTSTRAP_SEED", "CONFIDENCE", "POWER", "POWER_Z", "WILSON_Z", "bootstrap_mean",
           "episodes_for", "iqm", "oracle_share", "paired_mde", "performance_profile", "performance_profile_interval",
           "probability_of_improvement", "probability_of_improvement_interval", "stratified_bootstrap",
           "wilson_interval"]
