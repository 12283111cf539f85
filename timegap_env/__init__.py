"""TimeGapMonitor: a platoon simulator, a Bayesian time-gap monitor, control charts, and the
Gymnasium environment ``TimeGapMonitor-v0`` built from them (registered on import).

``simulate(...)`` runs a whole scenario without the environment and returns its :class:`Trajectory`.
"""

from gymnasium.envs.registration import register, registry

from timegap_env.config import EnvConfig
from timegap_env.leaders import LeaderProfile
from timegap_env.scenarios import SCENARIOS, make_leader
from timegap_env.simulation import Trajectory, simulate

ENV_ID = "TimeGapMonitor-v0"

if ENV_ID not in registry:
    register(
        id=ENV_ID,
        entry_point="timegap_env.env:TimeGapMonitorEnv",
        vector_entry_point="timegap_env.vector_env:TimeGapMonitorVectorEnv",
        max_episode_steps=EnvConfig().max_episode_steps,
    )

__all__ = ["ENV_ID", "SCENARIOS", "LeaderProfile", "Trajectory", "make_leader", "simulate"]
