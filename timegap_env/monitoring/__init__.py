"""Monitoring: what the followers measure, the Bayesian monitor of their time gap, and the charts on it.

In data-flow order:

- :mod:`~timegap_env.monitoring.sensors`: noisy spacing and speed readings with dropouts;
- :mod:`~timegap_env.monitoring.posterior`: the paper's Proposition, ``posterior(V, S, mu_b, Sigma_b, sigma2)``;
- :mod:`~timegap_env.monitoring.monitor`: :class:`TimeGapMonitor`, the Proposition streamed over a window;
- :mod:`~timegap_env.monitoring.charts`: Shewhart, EWMA and CUSUM charts and the paper's switching rule;
- :mod:`~timegap_env.monitoring.loop`: :class:`MonitoredPlatoon`, the simulator and all of the above per tick;
- :mod:`~timegap_env.monitoring.estimate`: ``estimate_time_gap``, the monitor over measured data of real cars.
"""

from timegap_env.monitoring.charts import CHARTS, ChartState, make_chart, switch_rule
from timegap_env.monitoring.estimate import TimeGapEstimate, estimate_time_gap
from timegap_env.monitoring.loop import MonitoredPlatoon
from timegap_env.monitoring.monitor import TimeGapMonitor
from timegap_env.monitoring.posterior import Moments, outside_probability, posterior, prior_precision
from timegap_env.monitoring.sensors import Readings, Sensors

__all__ = ["CHARTS", "ChartState", "Moments", "MonitoredPlatoon", "Readings", "Sensors", "TimeGapEstimate",
           "TimeGapMonitor", "estimate_time_gap", "make_chart", "outside_probability", "posterior", "prior_precision",
           "switch_rule"]
