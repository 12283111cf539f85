"""The measurements behind ``make bench`` (``python -m train.bench``), each a ratio against a reference run in the
same process: :mod:`~timegap_env.speed.cold` (first step in a child process), :mod:`~timegap_env.speed.vector`
(the native vector env at growing sizes, memory, batched reset), :mod:`~timegap_env.speed.single` (where a
single env's step goes), :mod:`~timegap_env.speed.ppo` (the env's share of PPO's time; needs the ``train``
extra) and :mod:`~timegap_env.speed.monitor` (the streaming monitor). They print and never assert: timing
depends on the machine.
"""
