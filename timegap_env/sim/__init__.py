"""The simulator: the platoon's physics, its string stability, and whole runs without the env.

- :mod:`~timegap_env.sim.platoon`: :class:`Platoon`, batched GLVD followers under the CTH controller;
- :mod:`~timegap_env.sim.stability`: the analytic string-stability check;
- :mod:`~timegap_env.sim.trajectory`: ``simulate(...) -> Trajectory``;
- :mod:`~timegap_env.sim.calibration`: the follower model fitted to recorded cars;
- :mod:`~timegap_env.sim.presets`: the followers calibrated to real commercial ACC cars (OpenACC).
"""

from timegap_env.sim.platoon import Platoon
from timegap_env.sim.presets import COMMERCIAL_ACC, acc_platoon, acc_presets
from timegap_env.sim.stability import StabilityReport, platoon_string_stability, string_stability
from timegap_env.sim.trajectory import Collision, Trajectory, simulate

__all__ = ["COMMERCIAL_ACC", "Collision", "Platoon", "StabilityReport", "Trajectory", "acc_platoon", "acc_presets",
           "platoon_string_stability", "simulate", "string_stability"]
