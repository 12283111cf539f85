"""The task behind ``TimeGapMonitor-v0`` for ``n_envs`` platoons at once: orchestration only.

Reset: each env draws its episode (:mod:`~timegap_env.envs.episodes`) and the monitored platoon
(:mod:`~timegap_env.monitoring.loop`) restarts on it. Step: the action becomes settings
(:mod:`~timegap_env.envs.action`), ``ticks_per_decision`` ticks run through the monitored
platoon, and the step is scored (:mod:`~timegap_env.envs.reward`) and added to the episode
totals (:mod:`~timegap_env.envs.totals`); the observation is :mod:`~timegap_env.envs.observation`'s.
The single env runs the task with ``n_envs = 1``, the native vector env with ``n_envs = N``:
same code, so they agree step by step.

A step is one compiled call that takes each env through every stage
(:func:`~timegap_env.envs.step_kernel.fused_step`), a recorded trace included; with SUMO's physics the same
stages run before and after its ticks (:func:`~timegap_env.envs.step_kernel.prepare_step`,
:func:`~timegap_env.envs.step_kernel.finish_step`). The tests hold it to the components' own methods composed
stage by stage (``tests/envs/reference.py``), bit for bit.
"""

from __future__ import annotations

import dataclasses
from collections import deque
from collections.abc import Mapping, Sequence
from typing import Any, NamedTuple

import numpy as np

from timegap_env.compiled import compiled_entry
from timegap_env.config import TIME_GAP_MIN_SPEED, EnvConfig
from timegap_env.envs.action import SettingLadder
from timegap_env.envs.episodes import Episodes, check_reset_options
from timegap_env.envs.info import TRUTH_PREFIX, VIEW_FLAGS, VIEW_FLOATS, InfoBlock, prefixed, write_info_envs
from timegap_env.envs.observation import FollowerState, observe_into
from timegap_env.envs.rendering import DEFAULT_TIME_WINDOW, RenderFrame
from timegap_env.envs.reward import REWARD_TERMS, StepReadouts
from timegap_env.envs.step_kernel import EnvParams, EnvState, StepScratch, env_dims, finish_step, fused_step, prepare_step
from timegap_env.envs.totals import EpisodeTotals
from timegap_env.monitoring.loop import MonitoredPlatoon
from timegap_env.sim.platoon import Platoon
from timegap_env.state import State


@dataclasses.dataclass(frozen=True)
class StepResult:
    """What one step returns for every env, arrays with a leading n_envs axis: the task's own, overwritten by the
    next step (copy what you keep)."""

    reward: np.ndarray  # (n_envs,)
    term_rows: np.ndarray  # (n_terms, n_envs) the reward terms in REWARD_TERMS order, each <= 0
    objective_rows: np.ndarray  # (n_terms, n_envs) each term's objective in its natural unit (reward.OBJECTIVES)
    cost: np.ndarray  # (n_envs,) the step's cost (reward.COST_TERMS), >= 0
    terminated: np.ndarray  # (n_envs,) a collision ended the episode
    truncated: np.ndarray  # (n_envs,) the episode ran out of time or leader profile

    @property
    def terms(self) -> dict[str, np.ndarray]:
        """Reward term -> (n_envs,), copies."""
        return {name: row.copy() for name, row in zip(REWARD_TERMS, self.term_rows)}


class TraceArrays(NamedTuple):
    """Env 0's monitor and chart at every traced tick."""

    t: np.ndarray  # (n_ticks,) time since reset [s]
    estimate: np.ndarray  # (n_ticks, n_followers) posterior mean of tau [s]
    center: np.ndarray  # (n_ticks, n_followers) the chart's centre line, the applied setting [s]


class Trace:
    """A record of env 0's estimates and chart centre lines, tick by tick, for rendering and profiles.

    ``keep``: how far back from its latest tick the trace reaches [s]; older ticks are dropped as new ones come, so
    its memory stays bounded however long the episode (the default: what a rendered chart shows). None keeps every
    tick (a whole-episode profile).
    """

    def __init__(self, n_followers: int, keep: float | None = DEFAULT_TIME_WINDOW) -> None:
        if keep is not None and not 0.0 <= keep < np.inf:
            raise ValueError(f"Trace keep = {keep!r}: must be a finite number of seconds >= 0, or None (every tick)")
        self.n_followers = n_followers
        self.keep = None if keep is None else float(keep)
        self._blocks: deque[TraceArrays] = deque()

    def add(self, block: TraceArrays) -> None:
        """Append a block of ticks (copied), then drop the ticks more than ``keep`` seconds before its last."""
        self._blocks.append(TraceArrays(*(np.array(part, dtype=float) for part in block)))
        if self.keep is None:
            return
        cutoff = self._blocks[-1].t[-1] - self.keep  # [s]
        while self._blocks[0].t[-1] < cutoff:  # wholly older than the window
            self._blocks.popleft()
        first = self._blocks[0]
        if first.t[0] < cutoff:
            self._blocks[0] = TraceArrays(*(part[first.t >= cutoff] for part in first))

    def clear(self) -> None:
        self._blocks.clear()

    @property
    def n_ticks(self) -> int:
        """Ticks held now [-]: at most ``keep / dt + 1`` with a ``keep``."""
        return sum(block.t.size for block in self._blocks)

    def arrays(self) -> TraceArrays:
        """Every tick held: all recorded so far, or with a ``keep`` those of the last ``keep`` seconds."""
        if not self._blocks:
            return TraceArrays(np.empty(0), np.empty((0, self.n_followers)), np.empty((0, self.n_followers)))
        return TraceArrays(*(np.concatenate(parts) for parts in zip(*self._blocks)))


class PlatoonTask:
    """Episodes, actions, observations and rewards of ``n_envs`` monitored platoons.

    ``trace``: None, or a :class:`Trace` of env 0 that every step adds to (see :meth:`start_trace`).
    """

    def __init__(self, config: EnvConfig, n_envs: int, info_layout: str = "v1") -> None:
        self.config = config
        self.n_envs = n_envs
        self.n_followers = config.platoon.n_followers
        self.ticks_per_decision = config.ticks_per_decision
        self.info_layout = info_layout  # the task's (timegap_env.tasks.INFO_LAYOUTS): what write_info fills
        self.state = State(EnvState, env_dims(config), n_envs)  # every env's arrays; the components hold views
        self.episodes = Episodes(config, n_envs, record_regime=info_layout != "v0", state=self.state, path=("leader",))
        self.ladder = SettingLadder(config, n_envs)
        self.loop = MonitoredPlatoon(config.platoon, config.monitor, config.chart, config.sensors, n_envs,
                                     physics=_physics(config, n_envs, self.state), state=self.state, path=("loop",))
        self.params = EnvParams.from_config(config)  # every constant of a step
        self.trace: Trace | None = None
        self._no_scores = (np.zeros((len(REWARD_TERMS), n_envs)), np.zeros((len(REWARD_TERMS), n_envs)),
                           np.zeros(n_envs))  # a reset's info: no step's terms, objectives, cost
        self._info_block = tuple(InfoBlock.empty(n_envs, self.n_followers, info_layout))  # monitor_info's
        self._no_info = tuple(InfoBlock.empty(0, self.n_followers, info_layout))  # a step writing no info
        self._scratch = tuple(StepScratch.empty(self.ticks_per_decision, self.n_followers))
        self._trace_block = np.empty((self.ticks_per_decision, 2, self.n_followers))  # env 0's ticks, when traced
        self._no_trace = np.empty((0, 2, self.n_followers))
        self._reset_once = False  # a step needs every env reset first
        self._compiled: dict[str, Any] = {}  # fused_step and write_info_envs compiled for the types they are handed
        self._result = self._step_result()

    def __getstate__(self) -> dict[str, Any]:
        """For copy and pickle: everything but the compiled entries (the next calls compile or load them again) and
        the views of the state (made again from the copy's)."""
        return {**self.__dict__, "_compiled": {}, "_result": None}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self._result = self._step_result()

    def _step_result(self) -> StepResult:
        """What every step writes, views of the state."""
        step = self.state.views.step
        return StepResult(reward=step.reward, term_rows=self.state.rows(("terms",)),
                          objective_rows=self.state.rows(("objectives",)), cost=step.cost,
                          terminated=step.terminated, truncated=step.truncated)

    totals = property(lambda self: self.state.views.totals, doc="Each env's :class:`EpisodeTotals` so far.")
    _readouts = property(lambda self: self.state.views.readouts, doc="The last step's :class:`StepReadouts`.")

    @staticmethod
    def bytes_per_env(config: EnvConfig) -> int:
        """Bytes of NumPy state each env of a task with ``config`` holds (what one more env costs) [B]."""
        native = dataclasses.replace(config, simulator="native")  # the same arrays, whatever computes the ticks
        two, one = PlatoonTask(native, 2), PlatoonTask(native, 1)
        others = _owned_bytes(two, two.state.blocks) - _owned_bytes(one, one.state.blocks)  # outside the state
        return others + one.state.bytes_per_env

    def close(self) -> None:
        """End what the simulator holds (SUMO's simulation; nothing natively)."""
        close = getattr(self.loop.platoon, "close", None)
        if close is not None:
            close()

    # ------------------------------------------------------------------ reset
    def reset(self, mask: np.ndarray, rngs: Sequence[np.random.Generator], options: Mapping[str, Any] | None) -> None:
        """Draw a new episode for every env in ``mask``, env i from ``rngs[i]``, all in one batch; ``options`` as in
        :meth:`~timegap_env.envs.episodes.Episodes.draw`."""
        options = check_reset_options(options)
        episodes, loop = self.episodes, self.loop
        envs = np.flatnonzero(mask)
        try:
            episodes.draw_many(envs, rngs, options)
            loop.degrade_many(envs, [episodes.degradations[env] for env in envs], episodes.packet_loss_keys[envs])
            loop.reset(episodes.leader_speed[:, 0], episodes.leader_accel[:, 0], mask=mask,
                       setting=episodes.initial_setting[:, None], noise_key=episodes.noise_keys,
                       dropout_probability=episodes.dropout_probability)  # SUMO starts here, and may fail
        except BaseException:  # the envs are half reset: they name no episode (the env shells refuse to step them)
            episodes.scenario[envs] = ""
            raise
        loop.platoon.set_v2v(self._v2v_during(loop.ticks), mask=mask)  # the others keep their last tick's
        step, readouts = self.state.views.step, self.state.views.readouts
        step.previous_accel[mask] = loop.platoon.a[mask, 1:]
        step.envelope[mask] = np.abs(loop.platoon.a[mask])
        readouts.min_ttc[mask] = np.inf
        readouts.jerk_squared[mask] = 0.0
        self.totals.restart(mask)
        observe_into(self._follower_state(), self.params.scales, step.observation, mask)
        self._reset_once = True

    def _v2v_during(self, ticks: np.ndarray) -> np.ndarray:
        """Each follower's V2V flag during tick ``ticks`` (..., n_envs) since reset: down while a degradation takes it
        down, and always without V2V (``platoon.v2v`` False)."""
        return self.loop.degradation.v2v_up(ticks) & self.config.platoon.v2v

    def start_trace(self, keep: float | None = DEFAULT_TIME_WINDOW) -> Trace:
        """Record env 0 at every tick from now on, holding the last ``keep`` seconds [s] (None: every tick; see
        :class:`Trace`); cleared at each reset by the env. Returns the trace."""
        self.trace = Trace(self.n_followers, keep)
        return self.trace

    # ------------------------------------------------------------------ step
    def step(self, action: np.ndarray) -> StepResult:
        """Apply the action (checked against the action space), run one decision interval of ticks, and score it."""
        return self._run_step(self.ladder.check(action))

    def _run_step(self, action: np.ndarray, block: tuple | None = None) -> StepResult:
        """:meth:`step` for an action that :meth:`SettingLadder.check` returned (the single env checks its own; the
        fused step checks nothing), writing each env's per-step info values into ``block`` (an
        :class:`~timegap_env.envs.info.InfoBlock` of every env as a plain tuple, or None: none written)."""
        if not self._reset_once:
            raise RuntimeError("PlatoonTask.step() before reset(): reset every env first")
        block = self._no_info if block is None else block
        n_written = block[0].shape[1]  # InfoBlock.floats' n_envs
        if n_written not in (0, self.n_envs):  # the compiled step checks no bounds
            raise ValueError(f"an InfoBlock of {n_written} envs: must be of n_envs = {self.n_envs} or 0")
        trace = self._no_trace if self.trace is None else self._trace_block
        if self.config.simulator == "native":  # the whole step in one compiled call
            arguments = (self.state.blocks, self._scratch, self.params, action, block, trace)
            if "step" not in self._compiled:  # for these types (SettingLadder.check gives every action one type)
                self._compiled["step"] = compiled_entry(fused_step, *arguments)
            self._compiled["step"](*arguments)
        else:  # the same step around another simulator's physics
            prepare_step(self.state.blocks, self._scratch, self.params, action)
            scratch = StepScratch(*self._scratch)
            physics = self.loop.platoon.advance(scratch.leader[0], scratch.leader[1], scratch.flags[0])
            scratch.floats[:4], scratch.flags[1] = physics[:4], physics.collisions
            finish_step(self.state.blocks, self._scratch, self.params, self.n_envs, block, trace)
        if self.trace is not None:  # env 0's ticks of this step
            ticks = self.loop.ticks[0] - self.ticks_per_decision + 1 + np.arange(self.ticks_per_decision)
            self.trace.add(TraceArrays(ticks * self.config.platoon.dt, trace[:, 0], trace[:, 1]))
        return self._result

    # ------------------------------------------------------------------ read-outs
    @property
    def scenario(self) -> np.ndarray:
        """The leader's name in each env's episode (n_envs,); "" where the last reset raised while drawing it."""
        return self.episodes.scenario

    def observation(self) -> np.ndarray:
        """Observations (n_envs, n_followers, len(FEATURES)) float32, the features in FEATURES order (a copy)."""
        return self.state.views.step.observation.copy()

    def _follower_state(self) -> FollowerState:
        """What the observation reads now (:mod:`~timegap_env.envs.observation`)."""
        moments, chart, platoon = self.loop.monitor.moments, self.loop.chart, self.loop.platoon
        return FollowerState(
            tau_mean=moments.mean_tau, tau_var=moments.var_tau, center=chart.center, side=chart.side,
            exceedances_in_window=chart.exceedances_in_window, run_length=chart.run_length, setting=platoon.setting,
            speed=platoon.v[:, 1:], v2v=platoon.v2v,
        )

    def monitor_info(self) -> dict[str, np.ndarray]:
        """The monitor's view now, what every info holds: arrays nothing else holds (rows of fresh copies), each
        (n_envs, n_followers). ``estimate``: the posterior mean of tau [s]; ``estimate_std`` [s]; ``setting``: tau*
        asked for [s]; ``lcl``, ``ucl``: the chart's limits [s]; ``alarm``; ``v2v``: the flag the follower sees (CACC
        when True); ``skipped_measurements`` since reset [-] (:func:`~timegap_env.envs.info.write_info_env`)."""
        self.write_info(self._info_block, scored=False)
        floats, flags, skipped, _ = self._info_block
        return {**dict(zip(VIEW_FLOATS, floats.copy())), **dict(zip(VIEW_FLAGS, flags.copy())),
                "skipped_measurements": skipped.copy()}

    def write_info(self, block: tuple, scored: bool) -> None:
        """Every env's per-step info values now into ``block`` (an InfoBlock of n_envs, a plain tuple), in one
        compiled pass (:func:`~timegap_env.envs.info.write_info_envs`): the monitor's view and, if ``scored``, the last
        step's scores (else zeros, a reset's)."""
        monitor, chart, platoon = self.loop.monitor, self.loop.chart, self.loop.platoon
        result = self._result
        scores = (result.term_rows, result.objective_rows, result.cost) if scored else self._no_scores
        arguments = (monitor.moments.mean_tau, monitor.moments.var_tau, platoon.setting, chart.center,
                     self.params.scales.half_width, chart.side, platoon.v2v, monitor.skipped, *scores, block)
        if "info" not in self._compiled:  # the same types at every call
            self._compiled["info"] = compiled_entry(write_info_envs, *arguments)
        self._compiled["info"](*arguments)

    def truth_info(self) -> dict[str, np.ndarray]:
        """What only the simulator knows, fresh arrays, each (n_envs, n_followers) unless noted: the platoon's true
        state now (``actual_time_gap``, ``ttc``, ``jerk``, ``collision``) and the ground truth as ``truth_<name>``
        (:meth:`ground_truth`). The opt-in part of the info (``truth_info=True``): working the ground truth out costs
        several times the rest of a step (``make bench``)."""
        platoon = self.loop.platoon
        return {
            # (s - s0) / v [s]; inf below TIME_GAP_MIN_SPEED, where it is not defined (never NaN)
            "actual_time_gap": np.where(platoon.v[:, 1:] >= TIME_GAP_MIN_SPEED, platoon.actual_time_gap, np.inf),
            "ttc": self._readouts.min_ttc.copy(),  # smallest time-to-collision during the step [s], inf if never closing
            "jerk": np.sqrt(self._readouts.jerk_squared / self.ticks_per_decision),  # RMS jerk during the step [m/s^3]
            "collision": platoon.collided.any(axis=1),  # (n_envs,)
            **prefixed(TRUTH_PREFIX, self.ground_truth()),
        }

    def objectives(self) -> tuple[np.ndarray, np.ndarray] | None:
        """With info layout "v1", the last step's objectives in natural units (n_terms, n_envs) and its cost
        (n_envs,) (the task's own arrays, see :class:`StepResult`); else None."""
        return None if self.info_layout == "v0" else (self._result.objective_rows, self._result.cost)

    def step_info(self, truth: bool) -> dict[str, np.ndarray]:
        """Every env's info now, flat (:mod:`~timegap_env.envs.info`), arrays nothing else holds, with a leading
        n_envs axis: :meth:`monitor_info`, and with ``truth`` :meth:`truth_info` too."""
        return {**self.monitor_info(), **self.truth_info()} if truth else self.monitor_info()

    def ground_truth(self) -> dict[str, np.ndarray]:
        """Each follower's degradation now, its true parameters and the smallest string-stable setting for them,
        arrays (n_envs, n_followers), and with info layout "v1" the leader's regime (n_envs,) (:meth:`~timegap_env.sim.degradation.DegradationTable.truth`): for
        oracles and evaluation, never in the observation."""
        loop, regime = self.loop, self.episodes.regime
        truth = loop.degradation.truth(loop.ticks, self._v2v_during(loop.ticks))
        if regime is not None:  # info layout "v1": the leader's regime now, (n_envs,)
            truth["regime"] = regime[np.arange(self.n_envs), np.minimum(loop.ticks, self.episodes.episode_ticks)]
        return truth

    def episode_summary(self) -> dict[str, np.ndarray]:
        """Episode statistics so far, each (n_envs,)."""
        return self.totals.summary(self.config)

    def fingerprint(self, env: int) -> str:
        """A hash of everything random that env ``env``'s current episode drew."""
        return self.episodes.fingerprint(env)

    def render_frame(self, history: float) -> RenderFrame:
        """What env 0 looks like now, with the last ``history`` seconds [s] of its trace (empty without one), at most
        what the trace keeps."""
        platoon, chart = self.loop.platoon, self.loop.chart
        now = self.loop.ticks[0] * self.config.platoon.dt
        trace = self.trace or Trace(self.n_followers)
        if trace.keep is not None and history > trace.keep:
            raise ValueError(f"render_frame history = {history} s: the trace keeps only the last {trace.keep} s "
                             f"(start_trace(keep=...))")
        arrays = trace.arrays()
        recent = arrays.t >= now - history
        centers = arrays.center[recent]
        half_width = self.params.scales.half_width
        return RenderFrame(
            t=now,
            x=platoon.x[0].copy(),
            v=platoon.v[0].copy(),
            vehicle_length=self.config.platoon.vehicle_length,
            history_t=arrays.t[recent],
            estimate_history=arrays.estimate[recent],
            lcl=chart.center[0] - half_width,
            ucl=chart.center[0] + half_width,
            center=chart.center[0].copy(),
            alarm=chart.alarm[0].copy(),
            v2v=platoon.v2v[0].copy(),
            collided=platoon.collided[0].copy(),
            lcl_history=centers - half_width,
            ucl_history=centers + half_width,
            center_history=centers,
            settling=chart.hold_off[0] > 0,
        )


def _physics(config: EnvConfig, n_envs: int, state: State) -> Platoon | None:
    """The platoon of ``config.simulator`` for ``n_envs`` envs on ``state`` (an :class:`EnvState`'s); None: the
    native one (MonitoredPlatoon's)."""
    if config.simulator == "native":
        return None
    if n_envs != 1:
        raise ValueError(f"simulator = 'sumo' with {n_envs} envs: libsumo runs one simulation per process; use one env "
                         "per process (num_envs=1; the processes or Ray backend spread episodes over processes)")
    from timegap_env.sim.sumo import SumoPlatoon  # libsumo only when asked for

    return SumoPlatoon(config.platoon, config.sumo, config.episode_duration, state, ("loop", "platoon"))


def _owned_bytes(root: Any, skip: tuple[np.ndarray, ...] = ()) -> int:
    """Bytes of every NumPy array reachable from ``root`` through attributes, containers and named tuples, each
    array's memory counted once (a view counts as its base), those of ``skip`` not at all [B]."""
    seen: set[int] = {id(array) for array in skip}
    total, stack = 0, [root]
    while stack:
        item = stack.pop()
        if isinstance(item, np.ndarray):
            while isinstance(item.base, np.ndarray):
                item = item.base
            if id(item) not in seen:
                seen.add(id(item))
                total += item.nbytes
            continue
        if id(item) in seen or isinstance(item, (str, bytes, int, float, type)):
            continue
        seen.add(id(item))
        if isinstance(item, (list, tuple, set, frozenset)):
            stack.extend(item)
        elif isinstance(item, dict):
            stack.extend(item.values())
        elif hasattr(item, "__dict__"):
            stack.extend(vars(item).values())
    return total
