"""What the scripts of ``train/`` share, in the installed library: the generic harness of experiments over the env.

- :mod:`~timegap_env.experiments.rollout`: the rollout harness, policies x configs x seeds -> one record per episode;
- :mod:`~timegap_env.experiments.registry`: the policy registry, name -> factory with its parameters;
- :mod:`~timegap_env.experiments.backends`: where independent pieces of work run (serial, or Ray tasks);
- :mod:`~timegap_env.experiments.stats`: bootstrap intervals of a mean, Wilson intervals of a rate.

The study code built on them (held-out groups, the value of information, the task map, ...) is not installed: it is
the package ``timegap_env.studies`` of the repository (issue 38).

Nothing here is imported by ``import timegap_env``: each module is imported where it is used.
"""
