"""The study code the scripts of ``train/`` share, in the package so that no script imports another module of
``train/``. Built on the harness, :mod:`timegap_env.experiments` (rollout, registry, backends, stats); paths into
the repository (its hyperparameters, the field data's defaults) assume a clone.

- :mod:`~timegap_env.studies.heldout`: the held-out evaluation (groups, seeds, every policy, statistics per group);
- :mod:`~timegap_env.studies.value`: constants, the lookup table and the oracles (the value of information), *the* oracle;
- :mod:`~timegap_env.studies.task_map`: the map of where reading the monitor can pay, and the default task's references;
- :mod:`~timegap_env.studies.crosscheck`: SUMO against the native simulator, the same leaders, settings and policies;
- :mod:`~timegap_env.studies.training`: what training, its learning curve and RLlib's runs agree on;
- :mod:`~timegap_env.studies.window_study`: the monitor window study's candidates and episodes.

Scripts import these modules, never anything else of ``train/``.
"""
