"""The Proposition: posterior() against the paper's dense formula, its priors and weights, bad input."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from timegap_env.monitoring.posterior import Prior, WindowSums, outside_probability, posterior, posterior_moments

PAPER_PRIOR_COV = np.array([[1e-4, -1e-5], [-1e-5, 0.125]])


def synthetic(rng: np.random.Generator, n: int, tau: float, s0: float) -> tuple[np.ndarray, np.ndarray]:
    """n speeds [m/s] in the paper's band and spacings S = s0 + tau V + noise [m]."""
    speed = rng.uniform(8.94, 35.76, n)
    return speed, s0 + tau * speed + rng.normal(0.0, 0.1, n)


def dense_posterior(V, S, mu_b, Sigma_b, sigma2, weights=None):
    """The Proposition written out with explicit inverses, as printed in the paper."""
    Z = np.column_stack([np.ones(len(V)), V])
    W = np.diag(np.ones(len(V)) if weights is None else weights)
    prior_inv = np.linalg.inv(Sigma_b)
    cov = np.linalg.inv(prior_inv + Z.T @ W @ Z / sigma2)
    return cov @ (Z.T @ W @ S / sigma2 + prior_inv @ mu_b), cov


def random_spd(rng: np.random.Generator) -> np.ndarray:
    std = rng.uniform(0.01, 1.0, 2)
    rho = rng.uniform(-0.9, 0.9)
    return np.array([[std[0] ** 2, rho * std[0] * std[1]], [rho * std[0] * std[1], std[1] ** 2]])


def assert_spd(cov: np.ndarray) -> None:
    assert np.all(np.isfinite(cov))
    np.testing.assert_array_equal(cov, np.swapaxes(cov, -1, -2))
    np.linalg.cholesky(cov)  # raises unless positive definite


@pytest.mark.parametrize("seed", range(5))
def test_posterior_matches_dense_formula(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 200))
    V = rng.uniform(0, 40, n)
    S = rng.uniform(0, 100, n)
    mu_b, Sigma_b, sigma2 = rng.normal(size=2), random_spd(rng), rng.uniform(0.01, 2.0)
    weights = rng.uniform(0, 1, n)
    for w in (None, weights):
        mean, cov = posterior(V, S, mu_b, Sigma_b, sigma2, weights=w)
        dense_mean, dense_cov = dense_posterior(V, S, mu_b, Sigma_b, sigma2, w)
        np.testing.assert_allclose(mean, dense_mean, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(cov, dense_cov, rtol=1e-9, atol=1e-15)


def test_posterior_paper_prior_and_data():
    rng = np.random.default_rng(0)
    V, S = synthetic(rng, 100, tau=1.6, s0=1.0)
    mean, cov = posterior(V, S, [1.0, 1.6], PAPER_PRIOR_COV, 0.01)
    dense_mean, dense_cov = dense_posterior(V, S, np.array([1.0, 1.6]), PAPER_PRIOR_COV, 0.01)
    np.testing.assert_allclose(mean, dense_mean, rtol=1e-10)
    np.testing.assert_allclose(cov, dense_cov, rtol=1e-8)
    assert mean[1] == pytest.approx(1.6, abs=0.01)


def test_posterior_without_data_is_the_prior():
    mean, cov = posterior([], [], [5.0, 1.6], PAPER_PRIOR_COV, 0.01)
    np.testing.assert_allclose(mean, [5.0, 1.6], rtol=1e-14)
    np.testing.assert_allclose(cov, PAPER_PRIOR_COV, rtol=1e-12)


def test_posterior_integer_weights_repeat_measurements():
    V, S = np.array([10.0, 20.0, 30.0]), np.array([21.0, 37.5, 53.0])
    weighted = posterior(V, S, [5.0, 1.6], PAPER_PRIOR_COV, 0.01, weights=[2, 0, 3])
    repeated = posterior([10, 10, 30, 30, 30], [21, 21, 53, 53, 53], [5.0, 1.6], PAPER_PRIOR_COV, 0.01)
    np.testing.assert_allclose(weighted[0], repeated[0], rtol=1e-12)
    np.testing.assert_allclose(weighted[1], repeated[1], rtol=1e-12)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"V": [1.0, np.nan]}, r"V\[1\] = nan"),
        ({"S": [1.0]}, "S has shape"),
        ({"V": [[1.0, 2.0]]}, "V has shape"),
        ({"mu_b": [1.0, 2.0, 3.0]}, "mu_b"),
        ({"Sigma_b": [[1.0, 0.0], [0.0, -1.0]]}, "Sigma_b .* positive definite"),
        ({"Sigma_b": [[1.0, 0.5], [0.4, 1.0]]}, "Sigma_b .* symmetric"),
        ({"sigma2": 0.0}, "sigma2 = 0.0"),
        ({"sigma2": float("inf")}, "sigma2 = inf"),
        ({"weights": [1.0, -1.0]}, "weights"),
        ({"V": [1e200, 1e200]}, "overflows"),
    ],
)
def test_posterior_rejects_bad_input(kwargs, message):
    args = {"V": [10.0, 20.0], "S": [21.0, 37.0], "mu_b": [5.0, 1.6], "Sigma_b": PAPER_PRIOR_COV, "sigma2": 0.01}
    args.update(kwargs)
    with pytest.raises(ValueError, match=message):
        posterior(**args)


def test_outside_probability_of_a_normal():
    assert outside_probability(0.0, 1.0, -1.0, 1.0) == pytest.approx(0.31731050786291415, rel=1e-14)  # 2 (1 - Phi(1))
    assert outside_probability(0.0, 4.0, -2.0, np.inf) == pytest.approx(0.15865525393145707, rel=1e-14)  # sd 2
    assert outside_probability(0.0, 1.0, -40.0, 40.0) == 0.0  # both tails underflow cleanly
    assert outside_probability(0.0, 1.0, 40.0, 50.0) == 1.0  # mean far below the band


@settings(max_examples=100, deadline=None)
@given(
    data=st.lists(st.tuples(st.floats(0, 100), st.floats(0, 1000)), max_size=50),
    mu_b=st.tuples(st.floats(-10, 10), st.floats(0, 5)),
    std=st.tuples(st.floats(1e-3, 10), st.floats(1e-3, 10)),
    rho=st.floats(-0.99, 0.99),
    sigma2=st.floats(1e-3, 10),
)
def test_posterior_is_finite_and_positive_definite(data, mu_b, std, rho, sigma2):
    V, S = np.array(data, dtype=float).reshape(-1, 2).T
    Sigma_b = np.array([[std[0] ** 2, rho * std[0] * std[1]], [rho * std[0] * std[1], std[1] ** 2]])
    mean, cov = posterior(V, S, mu_b, Sigma_b, sigma2)
    assert_spd(cov)
    assert np.all(np.isfinite(mean))


def test_posterior_moments_of_arrays_are_those_of_each_vehicle():
    """The monitor turns (n_envs, n_vehicles) window sums into posteriors in one call; each equals the scalar call."""
    rng = np.random.default_rng(3)
    n = rng.integers(0, 20, (3, 4)).astype(float)
    speed = rng.uniform(9.0, 35.0, (3, 4))
    sums = WindowSums(n, n * speed, n * speed**2 * 1.01, n * (5.0 + 1.6 * speed), n * speed * (5.0 + 1.7 * speed))
    prior = Prior.from_cov(5.0, PAPER_PRIOR_COV, 0.01)
    prior_tau = rng.uniform(0.6, 2.2, (3, 4))
    batch = posterior_moments(sums, prior_tau, prior)
    for e, i in np.ndindex(3, 4):
        one = posterior_moments(WindowSums(*(channel[e, i] for channel in sums)), prior_tau[e, i], prior)
        assert tuple(field[e, i] for field in batch) == tuple(one)


def test_prior_holds_the_precision_of_the_covariance():
    prior = Prior.from_cov(1.0, PAPER_PRIOR_COV, 0.01)
    np.testing.assert_allclose([[prior.p00, prior.p01], [prior.p01, prior.p11]], np.linalg.inv(PAPER_PRIOR_COV), rtol=1e-12)
    assert (prior.standstill_spacing, prior.noise_variance) == (1.0, 0.01)
    with pytest.raises(ValueError, match="positive definite"):
        Prior.from_cov(1.0, [[1.0, 2.0], [2.0, 1.0]], 0.01)

