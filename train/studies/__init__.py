"""The study code the scripts of ``train/`` share, beside them in the repository (not installed: issue 38). Built on
the installed harness, :mod:`timegap_env.experiments` (rollout, registry, backends, stats).

- :mod:`~train.studies.heldout`: the held-out evaluation (groups, seeds, every policy, statistics per group);
- :mod:`~train.studies.value`: constants, the lookup table and the oracles (the value of information), *the* oracle;
- :mod:`~train.studies.task_map`: the map of where reading the monitor can pay, and the default task's references;
- :mod:`~train.studies.crosscheck`: SUMO against the native simulator, the same leaders, settings and policies;
- :mod:`~train.studies.training`: what training, its learning curve and RLlib's runs agree on;
- :mod:`~train.studies.window_study`: the monitor window study's candidates and episodes.

Scripts import these modules, never another script.
"""
