"""``mo-TimeGapMonitor-v1`` driven by MO-Gymnasium's wrappers and MORL-Baselines' Envelope Q-learning (issue 24).

Slow and needing the ``mo`` extra (part of ``clients``): ``bash .ci/clients -k mo``. The tests skip, saying how to
install them, where the libraries are missing.

What they show: ``mo_gymnasium.make`` builds the env and its vector rewards stay inside ``reward_space``;
``MORecordEpisodeStatistics`` sums them per episode; ``LinearReward`` with a preset's weights gives back the scalar
``TimeGapMonitor-v1`` of that preset, step by step; and Envelope learns on three objectives, then acts for any weights.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator

import gymnasium as gym
import numpy as np
import pytest

from timegap_env import LATEST_ENV_ID, MO_ENV_ID
from timegap_env.config import REWARD_PRESETS, RewardWeights
from timegap_env.envs import REWARD_TERMS

pytestmark = pytest.mark.slow

INSTALL = "needs the mo extra: pip install -e '.[mo]' (part of clients; or run bash .ci/clients)"
mo_gym = pytest.importorskip("mo_gymnasium", reason=INSTALL)
from mo_gymnasium.wrappers import LinearReward, MORecordEpisodeStatistics  # noqa: E402

SHORT = {"episode_duration": 30.0}  # [s]: 30 decisions
OBJECTIVES = ["efficiency", "string_stability", "tracking"]
# The terms are each <= 0 and the weights >= 0, so a weighted sum never cancels: a relative tolerance of a few float32
# roundings (eps 1.2e-7) bounds the difference between the float32 dot product and the scalar env's float64 sum.
FLOAT32_RTOL = 1e-6


def _weights(name: str) -> np.ndarray:
    """A preset's RewardWeights as the float32 vector LinearReward takes, in REWARD_TERMS order."""
    weights = REWARD_PRESETS[name].weights
    return np.array([getattr(weights, term) for term in REWARD_TERMS], dtype=np.float32)


def test_reward_weights_fields_are_the_reward_terms_in_order() -> None:
    """So that a RewardWeights in field order (``dataclasses.astuple``) is a weight vector for the full reward vector."""
    assert tuple(field.name for field in dataclasses.fields(RewardWeights)) == REWARD_TERMS


def test_mo_gymnasium_make_gives_vector_rewards_inside_the_reward_space() -> None:
    env = mo_gym.make(MO_ENV_ID, config=SHORT)
    space, dim = env.unwrapped.reward_space, env.unwrapped.reward_dim
    assert isinstance(space, gym.spaces.Box) and space.dtype == np.float32
    assert dim == len(REWARD_TERMS) and space.shape == (dim,)
    chosen = mo_gym.make(MO_ENV_ID, objectives=OBJECTIVES, config=SHORT)
    assert chosen.unwrapped.reward_dim == 3 and chosen.unwrapped.reward_space.shape == (3,)
    rows = [REWARD_TERMS.index(name) for name in OBJECTIVES]

    env.reset(seed=0)
    chosen.reset(seed=0)
    rng = np.random.default_rng(0)
    steps, done = 0, False
    while not done:
        action = int(rng.integers(env.action_space.n))
        _, reward, terminated, truncated, _ = env.step(action)
        _, chosen_reward, *_ = chosen.step(action)
        steps, done = steps + 1, terminated or truncated
        assert isinstance(reward, np.ndarray) and reward.dtype == np.float32 and reward in space
        assert chosen_reward in chosen.unwrapped.reward_space
        np.testing.assert_array_equal(chosen_reward, reward[rows])  # objectives picks rows, in the order given
    assert steps == env.unwrapped.config.max_episode_steps == 30


def test_mo_record_episode_statistics_sums_the_step_vectors() -> None:
    env = MORecordEpisodeStatistics(mo_gym.make(MO_ENV_ID, config=SHORT))
    env.reset(seed=0)
    env.action_space.seed(0)
    for _ in range(2):  # the second episode's sum starts again from zero
        total, steps, done = np.zeros(len(REWARD_TERMS), np.float32), 0, False
        while not done:
            _, reward, terminated, truncated, info = env.step(env.action_space.sample())
            total += reward
            steps, done = steps + 1, terminated or truncated
        assert info["episode"]["r"].shape == (len(REWARD_TERMS),)
        np.testing.assert_allclose(info["episode"]["r"], total, rtol=FLOAT32_RTOL)
        assert info["episode"]["l"] == steps
        assert np.any(total < 0)
        env.reset()


@pytest.mark.parametrize("preset", sorted(REWARD_PRESETS))
def test_linear_reward_with_a_presets_weights_is_the_scalar_envs_reward(preset: str) -> None:
    """MO env (its config without weights) + LinearReward(preset) == TimeGapMonitor-v1 with reward_weights=preset."""
    weights = _weights(preset)
    linear = LinearReward(mo_gym.make(MO_ENV_ID, config=SHORT), weight=weights)
    scalar = gym.make(LATEST_ENV_ID, config={**SHORT, "reward_weights": preset})
    obs_linear, _ = linear.reset(seed=3)
    obs_scalar, _ = scalar.reset(seed=3)
    np.testing.assert_array_equal(obs_linear, obs_scalar)
    rng = np.random.default_rng(3)
    rewards, done = [], False
    while not done:
        action = int(rng.integers(scalar.action_space.n))
        obs_linear, r_linear, term_linear, trunc_linear, info_linear = linear.step(action)
        obs_scalar, r_scalar, term_scalar, trunc_scalar, info_scalar = scalar.step(action)
        np.testing.assert_array_equal(obs_linear, obs_scalar)
        assert (term_linear, trunc_linear) == (term_scalar, trunc_scalar)
        assert np.ndim(r_linear) == 0
        np.testing.assert_allclose(r_linear, r_scalar, rtol=FLOAT32_RTOL, atol=1e-7)
        np.testing.assert_allclose(info_linear["vector_reward"], info_scalar["vector_reward"], rtol=FLOAT32_RTOL,
                                   atol=1e-7)
        np.testing.assert_allclose(r_scalar, np.dot(weights.astype(np.float64), info_scalar["vector_reward"]),
                                   rtol=FLOAT32_RTOL, atol=1e-7)
        rewards.append(r_scalar)
        done = term_scalar or trunc_scalar
    assert len(rewards) == 30 and sum(rewards) < 0


@pytest.fixture
def one_torch_thread() -> Iterator[None]:
    """Envelope's small updates on one torch thread: measured on 2 cores, 3000 steps took 14 s each time on one
    thread, and 11-110 s on two (the intra-op pool stalls now and then)."""
    torch = pytest.importorskip("torch", reason=INSTALL)
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


def test_morl_baselines_envelope_learns_three_objectives_then_acts_for_any_weights(one_torch_thread: None) -> None:
    pytest.importorskip("morl_baselines", reason=INSTALL)
    import torch
    from morl_baselines.common.evaluation import policy_evaluation_mo
    from morl_baselines.multi_policy.envelope.envelope import Envelope

    torch.manual_seed(0)
    config = {"episode_duration": 60.0}  # [s]: 60 decisions
    env = MORecordEpisodeStatistics(mo_gym.make(MO_ENV_ID, objectives=OBJECTIVES, config=config))
    env.reset(seed=0)  # train() resets without a seed: its episodes carry on this seed's stream
    env.action_space.seed(0)  # the random actions before learning_starts
    agent = Envelope(env, net_arch=[64, 64], buffer_size=10_000, learning_starts=500, log=False, seed=0, device="cpu")
    agent.train(total_timesteps=3_000, eval_env=None)  # log=False: no wandb, no evaluations during training
    assert agent.global_step == 3_000
    assert agent.num_episodes >= 3_000 // 60  # episodes of at most 60 steps
    returns = np.array(env.return_queue)  # MORecordEpisodeStatistics' last (up to 100) episode returns
    assert returns.shape == (min(agent.num_episodes, env.return_queue.maxlen), 3) and np.all(np.isfinite(returns)) and np.all(returns <= 0)

    evaluation = mo_gym.make(MO_ENV_ID, objectives=OBJECTIVES, config=config)
    obs, _ = evaluation.reset(seed=1)
    for w in (np.array([1.0, 0.0, 0.0], np.float32), np.array([0.2, 0.3, 0.5], np.float32)):
        action = agent.eval(obs, w)
        assert evaluation.action_space.contains(action)

    w = np.full(3, 1 / 3, dtype=np.float32)
    evaluation.reset(seed=1)  # policy_evaluation_mo resets without a seed
    scalarized, _, vector, _ = policy_evaluation_mo(agent, evaluation, w=w, rep=1)
    low = evaluation.unwrapped.reward_space.low * 60  # every step's terms at their lowest
    assert vector.shape == (3,) and np.all(np.isfinite(vector))
    assert np.all(low <= vector) and np.all(vector <= 0)
    assert scalarized == pytest.approx(float(np.dot(w, vector)), rel=1e-5)
