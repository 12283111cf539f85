"""The leader: the human-driven vehicle every platoon follows, as a speed profile.

- :mod:`~timegap_env.leaders.profile`: :class:`LeaderProfile`, from speeds, accelerations or a CSV;
- :mod:`~timegap_env.leaders.synthetic`: seeded synthetic families (the paper's aggressive cycles, ...,
  and the held-out harsh ones: stop-and-go waves, emergency braking);
- :mod:`~timegap_env.leaders.regimes`: traffic that changes within an episode, a leader that strings regimes;
- :mod:`~timegap_env.leaders.ngsim`: real NGSIM I-80 drivers;
- :mod:`~timegap_env.leaders.openacc`: real commercial ACC platoons (OpenACC), and their lead cars;
- :mod:`~timegap_env.leaders.idm`: highway-env's IDM driver reacting to a disturbance;
- :mod:`~timegap_env.leaders.scenarios`: the leader families (``register_family`` adds one) and the named
  scenarios of ``make_leader`` and the env.
"""

from timegap_env.leaders.idm import idm_leader
from timegap_env.leaders.ngsim import default_ngsim_path, read_ngsim, vehicle_ids, vehicle_profile
from timegap_env.leaders.openacc import OpenAccRun, default_openacc_dir, openacc_paths, read_openacc
from timegap_env.leaders.profile import LeaderProfile
from timegap_env.leaders.regimes import REGIMES, RegimesConfig, regime_schedule  # its leader: make_leader("regimes")
from timegap_env.leaders.scenarios import (
    HELD_OUT_FAMILIES, SCENARIOS, LeaderFamily, get_scenario, make_leader, register_family,
)
from timegap_env.leaders.synthetic import (
    EmergencyBrakingConfig,
    StopAndGoConfig,
    aggressive_cycles,
    emergency_braking,
    hard_braking,
    sinusoid,
    stochastic_human,
    stop_and_go,
)

__all__ = [
    "HELD_OUT_FAMILIES", "REGIMES", "SCENARIOS", "EmergencyBrakingConfig", "LeaderFamily", "LeaderProfile",
    "OpenAccRun", "RegimesConfig", "StopAndGoConfig", "aggressive_cycles", "default_ngsim_path", "default_openacc_dir",
    "emergency_braking", "get_scenario", "hard_braking", "idm_leader", "make_leader", "openacc_paths", "read_ngsim",
    "read_openacc", "regime_schedule", "register_family", "sinusoid", "stochastic_human", "stop_and_go",
    "vehicle_ids", "vehicle_profile",
]
