"""The env step composed of the components' own methods, stage by stage over every env: the readable specification
the one compiled step (``timegap_env.envs.step_kernel.fused_step``) is held to, bit for bit.

    from tests.envs.reference import use_reference
    use_reference(env.task)   # env steps by reference_step from now on
"""

from __future__ import annotations

import functools

import numpy as np

from timegap_env.envs.observation import observe_into
from timegap_env.envs.reward import StepTicks, score_step
from timegap_env.envs.task import PlatoonTask, StepResult, TraceArrays


def reference_step(task: PlatoonTask, action: np.ndarray, block: tuple | None = None) -> StepResult:
    """``task``'s step for a checked ``action``: the settings, the monitored platoon's block of ticks, the scores,
    the totals and the observation, each through the component that owns it; the info's values into ``block``."""
    cfg, loop, platoon = task.config, task.loop, task.loop.platoon
    changed = loop.change_setting(task.ladder.settings(action.reshape(task.ladder.shape), platoon.setting))
    ticks = loop.ticks + np.arange(task.ticks_per_decision)[:, None]  # (n_ticks, n_envs), before each tick
    leader_speed, leader_accel = task.episodes.leader_at(ticks + 1)
    run = loop.run(leader_speed, leader_accel, task._v2v_during(ticks))
    physics, chart = run.physics, run.chart
    if task.trace is not None:
        task.trace.add(TraceArrays((ticks[:, 0] + 1) * cfg.platoon.dt, run.tau_mean[:, 0], chart.center[:, 0]))
    step = StepTicks(
        tau_mean=run.tau_mean, center=chart.center, applied_setting=physics.applied_setting, alarm=chart.alarm,
        exceedance=chart.exceedance, collisions=physics.collisions, leader_speed=leader_speed,
        leader_accel=leader_accel, speed=physics.speed, spacing=physics.spacing, accel=physics.accel,
    )
    outputs, readouts = task.state.views.step, task.state.views.readouts
    score = score_step(step, outputs.previous_accel, outputs.envelope, platoon.setting, changed,
                       task.params.reward, task.params.weights, readouts)
    task.totals.add_step(readouts, platoon.setting, changed, task.params.reward.gap_per_vehicle)
    outputs.previous_accel[:] = physics.accel[-1]
    result = task._result
    result.reward[:], result.term_rows[:], outputs.changed[:] = score.reward, score.terms, changed
    result.objective_rows[:], result.cost[:] = score.objectives, score.cost
    np.any(platoon.collided, axis=1, out=result.terminated)
    result.truncated[:] = (loop.ticks >= task.episodes.episode_ticks) & ~result.terminated
    observe_into(task._follower_state(), task.params.scales, outputs.observation, np.ones(task.n_envs, dtype=bool))
    if block is not None and block[0].shape[1]:
        task.write_info(block, scored=True)
    return result


def use_reference(task: PlatoonTask) -> None:
    """Make ``task`` step by :func:`reference_step`."""
    task._run_step = functools.partial(reference_step, task)  # type: ignore[method-assign]
