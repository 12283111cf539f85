"""Reproduce the paper's monitoring figures and numbers (Kontar & Ahn, Sec. 3).

The paper's experiment: five CACC followers at tau* = 1.6 s behind a leader
with aggressive acceleration/deceleration cycles (250 s), each follower's
time gap estimated by the Bayesian monitor and charted against
LCL / CL / UCL = 1.35 / 1.6 / 1.85 s; when vehicle 1 leaves the limits three
times within 35 s its setting switches to 1.0 s (limits 0.75 / 1.0 / 1.25 s).

Our leader is a seeded ``aggressive_cycles`` profile, not the paper's NGSIM
vehicle 1829, so the target is the shape of the results, not the digits. The
script runs ``--seeds`` leaders at once, reports on how many the rule fires,
and draws the figures for the first seed on which it fires.

Writes ``results/paper/fig_timegap_profiles.png``, ``results/paper/fig_switch.png``
and ``results/paper/summary.md``.

    python -m train.reproduce_paper [--seeds 50] [--out results/paper]
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from timegap_env import cli
from timegap_env.config import (
    MONITOR_PRESETS, AggressiveCyclesConfig, ChartConfig, MonitorConfig, PlatoonConfig, SensorConfig,
)
from timegap_env.leaders import aggressive_cycles, make_leader
from timegap_env.monitoring import MonitoredPlatoon, switch_rule

PLATOON = PlatoonConfig()  # the paper's Table 1: five followers, T = 0.45 s, K = 1, tau* = 1.6 s, s0 = 5 m

EXIT_WINDOW = 50.0  # the paper counts exits within 50 s [s]
GENTLE_JERK = 5.0  # a gentler leader for the sensitivity line of the summary [m/s^3]
SENSOR_SEED = 1


@dataclasses.dataclass(frozen=True)
class LoopRecord:
    """One closed-loop run of ``n_envs`` platoons, arrays (n_envs, n_ticks, n_followers)."""

    t: np.ndarray  # (n_ticks,) [s]
    estimate: np.ndarray  # posterior mean of tau [s]
    actual_time_gap: np.ndarray  # (s - s0) / v [s]
    setting: np.ndarray  # time gap setting tau* [s]
    lcl: np.ndarray  # [s]
    ucl: np.ndarray  # [s]
    exceedance: np.ndarray  # an excursion started this tick [bool]
    switch_tick: np.ndarray  # (n_envs,) tick of vehicle 1's switch, -1 if none


def run_loop(
    speeds: np.ndarray, accels: np.ndarray, *, apply_rule: bool, monitor: MonitorConfig = MonitorConfig()
) -> LoopRecord:
    """Drive platoons with leaders ``speeds``/``accels`` (n_envs, n_ticks); vehicle 1 follows the rule if asked."""
    chart_config = ChartConfig()
    loop = MonitoredPlatoon(PLATOON, monitor, chart_config, SensorConfig(), n_envs=speeds.shape[0],
                            seed=SENSOR_SEED)
    loop.reset(speeds[:, 0], accels[:, 0])
    vehicle_1 = np.zeros(PLATOON.n_followers, dtype=bool)
    vehicle_1[0] = True
    switch_tick = np.full(speeds.shape[0], -1)
    names = ("estimate", "actual_time_gap", "setting", "lcl", "ucl", "exceedance")
    rows: dict[str, list[np.ndarray]] = {name: [] for name in names}
    for k in range(speeds.shape[1]):
        if k > 0:
            _, state = loop.tick(speeds[:, k], accels[:, k])
            if apply_rule:
                fire = switch_rule(state.exceedances_in_window, state.center, chart_config) & vehicle_1
                switch_tick[fire.any(axis=1)] = k
                loop.change_setting(chart_config.switch_to, fire)
        rows["estimate"].append(loop.monitor.tau_mean)
        rows["actual_time_gap"].append(loop.platoon.actual_time_gap)
        rows["setting"].append(loop.platoon.setting.copy())
        rows["lcl"].append(loop.chart.lcl)
        rows["ucl"].append(loop.chart.ucl)
        rows["exceedance"].append(loop.chart.exceedance.copy())
    arrays = {name: np.stack(values, axis=1) for name, values in rows.items()}
    return LoopRecord(t=np.arange(speeds.shape[1]) * PLATOON.dt, switch_tick=switch_tick, **arrays)


def max_exits_within(exceedance: np.ndarray, window_ticks: int) -> int:
    """Most excursion starts in any ``window_ticks`` ticks of a (n_ticks,) series."""
    counts = np.convolve(exceedance.astype(int), np.ones(window_ticks, dtype=int), mode="valid")
    return int(counts.max()) if counts.size else int(exceedance.sum())


def plot_profiles(record: LoopRecord, env: int, path: Path) -> None:
    """Estimated time gap of vehicles 1-5 with LCL / CL / UCL (no switching), like the paper's Fig. 'profiles'."""
    n_followers = record.estimate.shape[2]
    fig, axes = plt.subplots(n_followers, 1, figsize=(10, 2.0 * n_followers), sharex=True, sharey=True)
    for i, ax in enumerate(axes):
        ax.plot(record.t, record.actual_time_gap[env, :, i], color="0.75", lw=1, label="actual (s − s0)/v")
        ax.plot(record.t, record.estimate[env, :, i], color="tab:blue", lw=1, label="posterior mean of τ")
        for limit, style in ((record.lcl, "--"), (record.setting, "-"), (record.ucl, "--")):
            ax.plot(record.t, limit[env, :, i], color="tab:red", ls=style, lw=1)
        ax.set_ylabel(f"vehicle {i + 1}\nτ [s]")
        ax.grid(alpha=0.3)
    axes[0].legend(loc="upper right", fontsize=8, ncol=2)
    axes[0].set_title("Time gap profiles and control limits (LCL / CL / UCL in red), τ* = 1.6 s")
    axes[-1].set_xlabel("time [s]")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_switch(fixed: LoopRecord, switched: LoopRecord, env: int, path: Path) -> None:
    """Vehicle 1 at 1.6 s throughout (top) and with the paper's rule switching it to 1.0 s (bottom)."""
    fig, axes = plt.subplots(2, 1, figsize=(10, 5.5), sharex=True)
    t_switch = switched.t[switched.switch_tick[env]]
    for ax, record, title in (
        (axes[0], fixed, "time gap setting 1.6 s throughout"),
        (axes[1], switched, f"the paper's rule switches vehicle 1 to 1.0 s at t = {t_switch:.1f} s"),
    ):
        ax.plot(record.t, record.estimate[env, :, 0], color="tab:blue", lw=1, label="posterior mean of τ")
        for limit, style in ((record.lcl, "--"), (record.setting, "-"), (record.ucl, "--")):
            ax.plot(record.t, limit[env, :, 0], color="tab:red", ls=style, lw=1)
        starts = record.t[record.exceedance[env, :, 0]]
        ax.plot(starts, record.estimate[env, record.exceedance[env, :, 0], 0], "kx", label="exceedance")
        ax.axvline(t_switch, color="0.5", lw=0.8, ls=":")
        ax.set_title(f"Vehicle 1: {title}", fontsize=10)
        ax.set_ylabel("τ [s]")
        ax.grid(alpha=0.3)
    axes[0].legend(loc="upper right", fontsize=8)
    axes[1].set_xlabel("time [s]")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=int, default=50, help="leader seeds 0..N-1 run at once")
    parser.add_argument("--out", type=Path, default=Path("runs/paper"))
    args = parser.parse_args()
    cli.output_dir(args.out)
    args.out.mkdir(parents=True, exist_ok=True)

    profiles = [make_leader("paper", seed) for seed in range(args.seeds)]
    speeds, accels = np.stack([p.speed for p in profiles]), np.stack([p.accel for p in profiles])
    fixed = run_loop(speeds, accels, apply_rule=False)
    switched = run_loop(speeds, accels, apply_rule=True)
    fired = np.flatnonzero(switched.switch_tick >= 0)
    if fired.size == 0:
        raise SystemExit(f"the rule fired on none of {args.seeds} seeds; try more --seeds")
    env = int(fired[0])

    chart = ChartConfig()
    dt = fixed.t[1] - fixed.t[0]
    ramp_time = abs(PLATOON.initial_setting - chart.switch_to) / PLATOON.setting_ramp_rate
    settle = switched.switch_tick[env] + int(round((ramp_time + 5.0) / dt))  # ramp, then 5 s to settle
    deviation_before = np.abs(fixed.estimate[env, settle:, 0] - fixed.setting[env, settle:, 0]).max()
    deviation_after = np.abs(switched.estimate[env, settle:, 0] - switched.setting[env, settle:, 0]).max()
    deviation_before_switch = np.abs(fixed.estimate[env, : switched.switch_tick[env], 0] - 1.6).max()
    ranges = [(fixed.estimate[env, :, i].min(), fixed.estimate[env, :, i].max()) for i in range(5)]
    spread = [high - low for low, high in ranges]
    exits_50 = max_exits_within(fixed.exceedance[env, :, 0], int(round(EXIT_WINDOW / dt)))
    lcl, ucl = fixed.lcl[env, 0, 0], fixed.ucl[env, 0, 0]
    lcl_after, ucl_after = switched.lcl[env, -1, 0], switched.ucl[env, -1, 0]
    leave = [bool(ranges[i][0] < lcl or ranges[i][1] > ucl) for i in (0, 1)]

    gentle = [aggressive_cycles(seed, AggressiveCyclesConfig(max_jerk=GENTLE_JERK)) for seed in range(args.seeds)]
    gentle_run = run_loop(np.stack([p.speed for p in gentle]), np.stack([p.accel for p in gentle]), apply_rule=True)
    gentle_fired = int((gentle_run.switch_tick >= 0).sum())

    paper_prior = run_loop(speeds[env : env + 1], accels[env : env + 1], apply_rule=False, monitor=MONITOR_PRESETS["paper"])
    paper_prior_bias = float(np.mean(paper_prior.estimate[0, 1:] - paper_prior.actual_time_gap[0, 1:]))
    default_bias = float(np.mean(fixed.estimate[env, 1:] - fixed.actual_time_gap[env, 1:]))

    plot_profiles(fixed, env, args.out / "fig_timegap_profiles.png")
    plot_switch(fixed, switched, env, args.out / "fig_switch.png")

    def holds(ok: bool) -> str:
        return "yes" if ok else "**no**"

    rows = [
        ("Limits at τ* = 1.6 s (LCL / CL / UCL)", "1.35 / 1.6 / 1.85", f"{lcl:.2f} / 1.6 / {ucl:.2f}",
         holds(np.allclose((lcl, ucl), (1.35, 1.85)))),
        ("Limits at τ* = 1.0 s", "0.75 / 1.0 / 1.25", f"{lcl_after:.2f} / 1.0 / {ucl_after:.2f}",
         holds(np.allclose((lcl_after, ucl_after), (0.75, 1.25)))),
        ("Vehicles 1–2: estimated time gap range [s]", "1.28–1.92",
         f"{ranges[0][0]:.2f}–{ranges[0][1]:.2f}, {ranges[1][0]:.2f}–{ranges[1][1]:.2f}",
         f"{holds(all(leave))} (vehicles 1, 2 leave the limits: {leave[0]}, {leave[1]})"),
        ("Vehicle 1: most exits within 50 s", "4", str(exits_50), holds(exits_50 >= chart.switch_exceedances)),
        ("Vehicles 3–5 vary less than 1–2 (string stability)", "yes",
         "spread " + " > ".join(f"{s:.2f}" for s in spread) + " s",
         holds(all(spread[i] < min(spread[0], spread[1]) for i in (2, 3, 4)))),
        ("Rule (3 exits within 35 s) switches vehicle 1 to 1.0 s", "yes",
         f"at t = {switched.t[switched.switch_tick[env]]:.1f} s; fires on {fired.size} of {args.seeds} seeds",
         holds(True)),
        ("Vehicle 1: max deviation from τ*, 1.6 s → 1.0 s [s]", "0.32 → 0.17",
         f"{deviation_before:.3f} → {deviation_after:.3f}", holds(deviation_after < deviation_before)),
    ]
    lines = [
        f"# Paper reproduction (`python -m train.reproduce_paper --seeds {args.seeds}`)",
        "",
        f"Leader: `aggressive_cycles` seed {env} (the first of seeds 0–{args.seeds - 1} on which the rule fires), "
        "250 s, 20–80 mph; five CACC followers, T = 0.45 s, K = 1, τ* = 1.6 s, s0 = 5 m; "
        f"sensor noise {SensorConfig().spacing_noise_std} m / {SensorConfig().speed_noise_std} m/s; "
        f"default monitor (prior s0 = {MonitorConfig().prior_standstill_spacing} m, window {MonitorConfig().window} s); "
        f"Shewhart chart N(τ*, {chart.baseline_std}²), L = {chart.limit_width}.",
        "",
        "| quantity | paper | ours | shape holds |",
        "|---|---|---|---|",
        *[f"| {name} | {paper} | {ours} | {ok} |" for name, paper, ours, ok in rows],
        "",
        f"Max deviations compare the same stretch of time, from {switched.t[settle]:.1f} s (the switch, the "
        f"{ramp_time:.0f} s ramp and 5 s to settle) to 250 s, under 1.6 s (run without the rule) and under 1.0 s. "
        f"Before the switch vehicle 1's largest deviation from 1.6 s is {deviation_before_switch:.3f} s.",
        "",
        f"Prior bias: with the paper's printed prior (s0 = {MONITOR_PRESETS['paper'].prior_standstill_spacing} m "
        f"against the simulator's 5 m) the estimate is off the actual time gap by {paper_prior_bias:+.3f} s on "
        f"average; with the default prior by {default_bias:+.4f} s.",
        "",
        f"Sensitivity: how often the rule fires depends on how abruptly the leader changes its acceleration. "
        f"With the default leader (max jerk {AggressiveCyclesConfig().max_jerk:g} m/s³) it fires on {fired.size} of "
        f"{args.seeds} seeds; with a gentler one (max jerk {GENTLE_JERK:g} m/s³) on {gentle_fired} of {args.seeds}. "
        "The paper's single NGSIM leader had four exits within 50 s; ours have fewer, mostly above the UCL.",
    ]
    text = "\n".join(lines) + "\n"
    (args.out / "summary.md").write_text(text)
    print(text)


if __name__ == "__main__":
    cli.run(main, "python -m train.reproduce_paper")
