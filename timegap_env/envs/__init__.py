"""The environment ``TimeGapMonitor-v0`` and what it is made of.

In data-flow order: :mod:`~timegap_env.envs.episodes` (what each reset draws),
:mod:`~timegap_env.envs.action` (indices to settings), :mod:`~timegap_env.envs.task`
(the orchestration, batched over envs), :mod:`~timegap_env.envs.observation`,
:mod:`~timegap_env.envs.reward` and :mod:`~timegap_env.envs.totals` (what the agent sees and is
scored on), then the Gymnasium shells :mod:`~timegap_env.envs.env` and
:mod:`~timegap_env.envs.vector_env`, the drawing in :mod:`~timegap_env.envs.rendering`, and the
Stable-Baselines3 adapter :mod:`~timegap_env.envs.sb3` (import it yourself: it loads SB3 and torch).
"""

from timegap_env.envs.env import TimeGapMonitorEnv
from timegap_env.envs.observation import FEATURES, FollowerView, decode_observation, observation_space
from timegap_env.envs.reward import REWARD_TERMS
from timegap_env.envs.vector_env import TimeGapMonitorVectorEnv

__all__ = ["FEATURES", "REWARD_TERMS", "FollowerView", "TimeGapMonitorEnv", "TimeGapMonitorVectorEnv",
           "decode_observation", "observation_space"]
