"""What the scripts of ``train/`` share, in the installed library: experiments over the env.

- :mod:`~timegap_env.experiments.rollout`: the rollout harness, policies x configs x seeds -> one record per episode;
- :mod:`~timegap_env.experiments.registry`: the policy registry, name -> factory with its parameters;
- :mod:`~timegap_env.experiments.heldout`: the held-out evaluation (groups, seeds, every policy, statistics per group);
- :mod:`~timegap_env.experiments.backends`: where independent pieces of work run (serial, or Ray tasks);
- :mod:`~timegap_env.experiments.stats`: bootstrap intervals of a mean, Wilson intervals of a rate;
- :mod:`~timegap_env.experiments.value`: constants, the lookup table and the oracles (the value of information);
- :mod:`~timegap_env.experiments.training`: what training, its learning curve and RLlib's runs agree on;
- :mod:`~timegap_env.experiments.window_study`: the monitor window study's candidates and episodes.

Nothing here is imported by ``import timegap_env``: each module is imported where it is used.
"""
