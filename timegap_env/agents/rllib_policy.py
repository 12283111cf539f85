"""A PPO policy trained by Ray RLlib (``train/train_rllib.py``) behind the same interface as
:class:`timegap_env.agents.learned.LearnedPolicy`, for ``train.evaluate``.

    policy = RLlibPolicy.load("results/v0/rllib")       # the run directory, or its checkpoint/ (algo.save's)
    action, _ = policy.predict(obs, deterministic=True)

Only the learner's RLModule is read (``<checkpoint>/learner_group/learner/rl_module/default_policy``),
without starting Ray or the env runners; the env it was trained in (its action mode) comes from the
checkpoint's ``env.json``, which ``train.train_rllib`` writes beside RLlib's files. The run used no
observation filter (the env's features are already scaled), so observations go in as they are.
Loading needs Ray (the ``ray`` extra); importing this module does not, nor torch (:func:`find_checkpoint`
tells a script whether a path is an RLlib run before it pays for them).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from gymnasium import spaces

from timegap_env.agents.protocol import ENV_FILE, RunFileError, check_spaces, read_env_file

CHECKPOINT_DIR = "checkpoint"  # train.train_rllib's algo.save directory in a run directory
CHECKPOINT_MARKER = "rllib_checkpoint.json"  # RLlib writes it at the top of every checkpoint
MODULE_PATH = ("learner_group", "learner", "rl_module", "default_policy")  # the RLModule inside a checkpoint
ACTION_SPACES = {"platoon": spaces.Discrete, "relative": spaces.Discrete, "per_vehicle": spaces.MultiDiscrete}


def find_checkpoint(path: str | Path) -> Path | None:
    """The RLlib checkpoint ``path`` is (a directory holding ``rllib_checkpoint.json``) or holds as ``checkpoint/``;
    None if neither."""
    path = Path(path)
    for candidate in (path, path / CHECKPOINT_DIR):
        if (candidate / CHECKPOINT_MARKER).is_file():
            return candidate
    return None


class RLlibPolicy:
    """An RLlib RLModule as a policy: ``predict`` takes one observation (obs_dim,) or a batch (n_envs, obs_dim) and
    returns the module's actions (deterministic: the most likely, row by row, whatever the batch)."""

    def __init__(self, module: Any, action_mode: str, name: str = "RLlib PPO") -> None:
        if action_mode not in ACTION_SPACES or not isinstance(module.action_space, ACTION_SPACES[action_mode]):
            raise ValueError(f"action_mode = {action_mode!r}: does not fit module.action_space = {module.action_space}")
        module.eval()
        self.module = module
        self.action_mode = action_mode
        self.name = name
        self._inference = module.get_inference_action_dist_cls()
        self._exploration = module.get_exploration_action_dist_cls()

    @classmethod
    def load(cls, path: str | Path, name: str = "RLlib PPO", threads: int | None = 1) -> RLlibPolicy:
        """Load ``path``, a checkpoint directory of ``train.train_rllib`` (``algo.save``'s, with its ``env.json``)
        or a run directory holding one as ``checkpoint/``, on the CPU. A missing directory or file raises
        FileNotFoundError; a module or env.json that cannot be used or do not fit each other (another action space,
        as relative mode's Discrete(3) read as platoon mode's Discrete(9), or observations of another shape),
        RunFileError naming it. ``threads``: torch's threads from now on (None: leave them; one by default, as
        :meth:`timegap_env.agents.learned.LearnedPolicy.load`: the module is small and the simulator's threads need the cores)."""
        checkpoint = find_checkpoint(path)
        if checkpoint is None:
            raise FileNotFoundError(f"path = {str(path)!r}: no RLlib checkpoint (no {CHECKPOINT_MARKER} in it or in "
                                    f"its {CHECKPOINT_DIR}/)")
        module_dir = checkpoint.joinpath(*MODULE_PATH)
        if not module_dir.is_dir():
            raise RunFileError(f"{checkpoint}: an RLlib checkpoint without the RLModule {module_dir}")
        env_path = checkpoint / ENV_FILE
        if not env_path.is_file():
            raise FileNotFoundError(f"path = {str(path)!r}: no {env_path} (train.train_rllib writes it)")
        run = read_env_file(env_path)
        if run.frame_stack != 1 or run.normalize:  # train.train_rllib stacks no frames and uses no observation filter
            raise RunFileError(f"{env_path}: frame_stack = {run.frame_stack}, normalize = {run.normalize}: an RLlib "
                               "run is read with neither (train.train_rllib writes frame_stack 1 and no filter)")
        # Ray: slow to import, and only in the clients venv
        import torch
        from ray.rllib.core.rl_module.rl_module import RLModule

        if threads is not None:
            torch.set_num_threads(threads)

        try:
            module = RLModule.from_checkpoint(module_dir.resolve())
        except Exception as error:  # RLlib raises FileNotFoundError, pickle's and torch's errors for a bad directory
            raise RunFileError(f"{module_dir}: not a readable RLlib RLModule ({type(error).__name__}: {error})") \
                from error
        try:
            policy = cls(module, run.action_mode, name)
        except ValueError as error:
            raise RunFileError(f"{env_path} does not fit the module {module_dir}: {error}") from error
        check_spaces(run, module.action_space, module.observation_space.shape, module_dir)
        return policy

    @property
    def observation_shape(self) -> tuple[int, ...]:
        """Shape of one observation the policy takes."""
        return tuple(self.module.observation_space.shape)

    def predict(
        self,
        observation: np.ndarray,
        state: Any = None,
        episode_start: np.ndarray | None = None,
        deterministic: bool = True,
    ) -> tuple[np.ndarray, Any]:
        """The module's actions for ``observation``; ``state`` is passed back unchanged (the module is
        feed-forward) and ``episode_start`` is not needed. ``deterministic=False`` samples from torch's generator."""
        import torch
        from ray.rllib.core.columns import Columns

        obs = np.ascontiguousarray(observation, dtype=np.float32)  # torch takes no negative strides (obs[::-1])
        if obs.shape[-1:] != self.observation_shape or obs.ndim not in (1, 2):
            raise ValueError(f"observation of shape {obs.shape}: must be {self.observation_shape} or "
                             f"(n_envs, *{self.observation_shape})")
        batch = obs[None] if obs.ndim == 1 else obs
        with torch.no_grad():
            logits = self.module.forward_inference({Columns.OBS: torch.from_numpy(batch)})[Columns.ACTION_DIST_INPUTS]
            if deterministic:
                actions = self._inference.from_logits(logits).to_deterministic().sample()
            else:
                actions = self._exploration.from_logits(logits).sample()
        actions = actions.numpy()
        return (actions[0] if obs.ndim == 1 else actions), state

    def __repr__(self) -> str:
        return f"RLlibPolicy({self.name!r}, action_mode={self.action_mode!r})"
