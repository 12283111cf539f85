"""What training and evaluation agree on: the seed split and the files of a trained run.

Training (``train/train_ppo.py``) seeds its envs below ``EVAL_SEED_START``; the held-out
evaluation (``train/evaluate.py``) seeds its episodes from ``EVAL_SEED_START`` on, so no
evaluation episode was seen in training. A trained run is a directory holding ``MODEL_FILE``,
``ENV_FILE`` (JSON: ``env_kwargs``, the ``gym.make`` keyword arguments of the env it was trained
in, its action mode among them, and ``frame_stack``, the observations the model reads at once) and, when observations were normalised, ``VECNORMALIZE_FILE`` (all three
read by ``agents.learned``).
"""

EVAL_SEED_START = 10_000  # evaluation seeds are >= this, training seeds < this [-]
MODEL_FILE = "model.zip"  # the SB3 model of a run
VECNORMALIZE_FILE = "vecnormalize.pkl"  # SB3 VecNormalize statistics of a run, if it normalised
ENV_FILE = "env.json"  # the env a run was trained in and its frame stacking (JSON)
