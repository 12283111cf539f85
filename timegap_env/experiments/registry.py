"""The policy registry: a policy's name -> its factory, the action mode it acts in, and its parameters.

Every script names policies through it (``train.evaluate --policies``, a sweep's ``policies:``, ``train.tune_rule``'s
references), so a new policy is one :func:`register` call::

    register("my_rule", MyRule, "platoon", "what it does", threshold=3)
    policy = make("my_rule", {"preferred_setting": 1.0})   # MyRule(the default task's config in platoon mode, threshold=3)

``make(name, config)`` builds the policy for the env of ``config`` (an EnvConfig, or overrides of the default task's config) in the
policy's own action mode. Besides the registered names, ``fixed_<setting>`` holds one ladder level for the whole
episode (``fixed_1.6``), ``oracle`` is *the* oracle of the study code's ``value`` module (measured on training
and selection seeds: its ``make_oracle``) and ``ppo`` a trained run (:func:`load_learned`).
"""

from __future__ import annotations

import csv
import dataclasses
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from timegap_env.agents.policies import ChartStepPolicy, FixedPolicy, PaperRulePolicy, V2VAwarePolicy, as_config, seconds
from timegap_env.agents.protocol import MODEL_FILE
from timegap_env.config import EnvConfig

FIXED_PREFIX = "fixed_"  # fixed_<setting [s]>: one ladder level held for the whole episode
ORACLE = "oracle"  # the oracle, chosen on selection seeds (reads the ground truth)
PPO = "ppo"  # a trained run: an SB3 model (zip or run directory) or an RLlib run


@dataclasses.dataclass(frozen=True)
class PolicySpec:
    """A registered policy: ``factory(config, **parameters)`` builds it for ``config`` in ``action_mode``."""

    name: str
    factory: Callable[..., Any]
    action_mode: str  # the env's action mode the policy acts in ("platoon" or "per_vehicle")
    description: str = ""
    parameters: dict[str, Any] = dataclasses.field(default_factory=dict)

    def make(self, config: EnvConfig | Mapping[str, Any] | None = None, **parameters: Any) -> Any:
        """The policy for ``config`` in ``action_mode``, ``parameters`` over the registered ones."""
        return self.factory(in_mode(config, self.action_mode), **{**self.parameters, **parameters})


POLICIES: dict[str, PolicySpec] = {}


def in_mode(config: EnvConfig | Mapping[str, Any] | None, action_mode: str) -> EnvConfig:
    """``config`` (an EnvConfig, or overrides of the default task's config, or None: that config) with
    ``action_mode``."""
    return as_config(config).with_overrides({"action_mode": action_mode})


def register(name: str, factory: Callable[..., Any], action_mode: str = "platoon", description: str = "",
             **parameters: Any) -> PolicySpec:
    """Register ``factory(config, **parameters)`` as ``name``; ``ValueError`` if the name is taken or reserved."""
    if name in POLICIES or name in (ORACLE, PPO) or name.startswith(FIXED_PREFIX):
        raise ValueError(f"policy name {name!r}: already registered or reserved")
    spec = PolicySpec(name, factory, action_mode, description, dict(parameters))
    POLICIES[name] = spec
    return spec


register("rule_platoon", PaperRulePolicy, "platoon", "the paper's rule, one setting for the platoon")
register("rule_per_vehicle", PaperRulePolicy, "per_vehicle", "the paper's rule, a setting per follower")
register("chart_step", ChartStepPolicy, "platoon", "the chart-step rule (tuned by train.tune_rule), platoon-wide")
register("chart_step_per_vehicle", ChartStepPolicy, "per_vehicle", "the chart-step rule, a setting per follower")
register("v2v_aware", V2VAwarePolicy, "platoon", "a setting by the V2V flags, platoon-wide")
register("v2v_aware_per_vehicle", V2VAwarePolicy, "per_vehicle", "a setting by the V2V flags, per follower")


def fixed_name(setting: float) -> str:
    """The registry's name of the fixed policy at ``setting`` [s]: ``fixed_1.6``."""
    return f"{FIXED_PREFIX}{seconds(setting)}"


def fixed_names(config: EnvConfig | None = None) -> list[str]:
    """A fixed policy's name per ladder level of ``config`` (default: the default ladder), smallest first."""
    return [fixed_name(level) for level in as_config(config).setting_levels]


def is_known(name: str) -> bool:
    """Whether ``name`` names a policy: registered, ``fixed_<setting>``, ``oracle`` or ``ppo``."""
    return name in POLICIES or name.startswith(FIXED_PREFIX) or name in (ORACLE, PPO)


def known() -> list[str]:
    """Every name, sorted, with ``fixed_<setting>`` for the fixed policies."""
    return sorted([*POLICIES, f"{FIXED_PREFIX}<setting>", ORACLE, PPO])


def make(name: str, config: EnvConfig | Mapping[str, Any] | None = None, **parameters: Any) -> Any:
    """Policy ``name`` (a registered one or ``fixed_<setting>``) built for the env of ``config`` in its own action
    mode, ``parameters`` over its registered ones (``make("chart_step", k_up=2)``); ``ValueError`` for another name
    (``oracle``: the study code's ``value.make_oracle``; ``ppo``: :func:`load_learned`)."""
    if name.startswith(FIXED_PREFIX):
        text = name[len(FIXED_PREFIX):]
        try:
            setting = float(text)
        except ValueError:
            raise ValueError(f"{FIXED_PREFIX}<setting>: {text!r} is not a number of seconds") from None
        return FixedPolicy(setting, in_mode(config, "platoon"), **parameters)
    if name not in POLICIES:
        raise ValueError(f"policy {name!r}: unknown; known: {known()}")
    return POLICIES[name].make(config, **parameters)


class LearnedPolicyError(ValueError):
    """A trained run that cannot be loaded, or whose observations do not fit the env."""


def find_run(model: Path) -> Path | None:
    """The RLlib checkpoint of ``model`` if it is an RLlib run (None otherwise)."""
    from timegap_env.agents.rllib_policy import find_checkpoint

    return find_checkpoint(model)


def learned_exists(model: Path) -> bool:
    """Whether ``model`` is an SB3 model zip, a run directory holding one, or an RLlib run."""
    return model.is_file() or (model / MODEL_FILE).is_file() or find_run(model) is not None


def tuned_chart_step(path: Path) -> dict[str, float]:
    """The best cell of a ``train.tune_rule`` run's tuning.csv: ``k_up``, ``quiet_time`` [s], ``min_setting`` [s];
    ``ValueError`` naming the file if it has none."""
    try:
        with open(path, newline="", encoding="utf-8") as file:
            best = [row for row in csv.DictReader(file) if row.get("best") == "1"]
        if len(best) != 1:
            raise ValueError(f"{len(best)} rows with best = 1")
        row = best[0]
        return {"k_up": int(row["k_up"]), "quiet_time": float(row["quiet_time"]), "min_setting": float(row["min_setting"])}
    except (OSError, UnicodeDecodeError, csv.Error, ValueError, KeyError, TypeError) as error:
        raise ValueError(f"--chart-step-tuning {path}: not a tune_rule tuning.csv with one best cell ({error})") from error


def load_learned(model: Path, config: EnvConfig | None = None) -> Any:
    """The learned policy of ``model`` (an SB3 zip or run directory, or an RLlib run), loaded as it was trained
    (``LearnedPolicy.load``: ``env.json``, its statistics; torch on one thread), checked to take the observations of
    ``config``'s env (default: the default env); ``LearnedPolicyError`` naming what does not fit."""
    from timegap_env.agents.learned import LearnedPolicy, RunFileError  # torch is slow to import; only when needed
    from timegap_env.envs.observation import observation_space

    rllib = find_run(model)
    policy: RLlibPolicy | LearnedPolicy
    try:
        if rllib is not None:
            from timegap_env.agents.rllib_policy import RLlibPolicy  # loading needs the ray extra

            policy = RLlibPolicy.load(rllib)
        else:
            policy = LearnedPolicy.load(model)
    except (RunFileError, FileNotFoundError) as error:
        raise LearnedPolicyError(str(error)) from error
    expected = observation_space(as_config(config)).shape
    if policy.observation_shape != expected:
        raise LearnedPolicyError(f"--model {model}: takes observations of shape {policy.observation_shape}, the env "
                                 f"gives {expected}")
    return policy


__all__ = ["FIXED_PREFIX", "LearnedPolicyError", "ORACLE", "POLICIES", "PPO", "PolicySpec", "fixed_name", "fixed_names",
           "tuned_chart_step",
           "in_mode", "is_known", "known", "learned_exists", "load_learned", "make", "register"]
