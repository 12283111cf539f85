"""Policies for ``TimeGapMonitor-v0`` behind Stable-Baselines3's ``predict``.

- :mod:`timegap_env.agents.policies`: the paper's rule, fixed settings, a V2V-aware heuristic;
- :mod:`timegap_env.agents.learned`: a trained SB3 model with the observation scaling it was trained under
  (imports SB3 and torch: import it yourself);
- :mod:`timegap_env.agents.protocol`: the seed split between training and evaluation, and a run's files.
"""

from timegap_env.agents.policies import FixedPolicy, NamedPolicy, PaperRulePolicy, Policy, V2VAwarePolicy, fixed_policies

__all__ = ["FixedPolicy", "NamedPolicy", "PaperRulePolicy", "Policy", "V2VAwarePolicy", "fixed_policies"]
