"""TimeGapMonitor: a platoon simulator, a Bayesian time-gap monitor and control charts.

``simulate(...)`` runs a whole scenario and returns its :class:`Trajectory`.
"""

from timegap_env.leaders import LeaderProfile
from timegap_env.scenarios import SCENARIOS, make_leader
from timegap_env.simulation import Trajectory, simulate

__all__ = ["SCENARIOS", "LeaderProfile", "Trajectory", "make_leader", "simulate"]
