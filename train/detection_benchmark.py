"""How fast does each detector find trouble, at the same false-alarm rate? Labelled episodes, one table.

    python -m train.detection_benchmark [--episodes 32] [--out results/monitoring] [--backend serial|ray] [--address A]

Episodes: the env's monitored platoon (sensors with the default noise, the env's Bayesian monitor)
behind the default leader families, 250 s, the setting held at each of ``SETTINGS``. Nominal
episodes, and per degradation kind (``timegap_env.sim.degradation``) at ``SIZES`` of its range,
every follower degraded from ``ONSET`` on (a commercial ACC is one from the start; its delay counts
from the end of the warm-up).

Detectors, each a statistic charted against the setting (centre line) by the package's charts
(``timegap_env.monitoring.charts``) with one free threshold (the chart's width):

- ``bayes_shewhart``, ``bayes_ewma``, ``bayes_cusum``: the Bayesian estimate (the paper's monitor),
  Shewhart (the paper's chart), EWMA (lambda 0.2) and CUSUM (k = 0.5 sigma);
- ``raw_shewhart``, ``raw_ewma``: the raw instantaneous (S - s0) / V of each reading (NaN below
  1 m/s charts the centre line);
- ``rls_shewhart``: recursive least squares with forgetting ``RLS_FORGETTING`` on S = s0 + tau V
  (``timegap_env.monitoring.detectors``), the usual online ACC identification.

Matched false alarms: on nominal calibration episodes (seeds below ``EVAL_SEED_START``), each
statistic's in-control mean and std of its deviation from the setting (Phase I) give its chart's
centre (setting + mean) and baseline sigma (so the CUSUM's allowance is 0.5 of it), and its width is the smallest giving at most
``TARGET_FALSE_ALARMS`` excursion starts per follower-hour; then on held-out episodes (seeds from ``EVAL_SEED_START``): false alarms per hour on
nominal driving (ARL0), and per degraded condition the detection rate (a follower with an excursion
start within the 150 s after onset) and the delay from onset to the first (ARL1: mean, median,
90th percentile). The first ``WARM_UP`` seconds of every episode are not charted (the monitor's
window fills, RLS converges). Real nominal driving: the OpenACC runs (``read_openacc``; ACC and
people driving), each follower charted around its own median statistic, with the same widths:
false alarms per hour of driving (skipped, saying so, without the data). Writes ``detection.md``,
``detection.csv`` and ``detection.png`` to ``--out``; reruns give the same files.

Pieces of work for ``timegap_env.experiments.backends``: each setting's calibration, then each (setting, condition)
batch of held-out episodes with its detectors, then each setting's OpenACC false alarms.
``--backend serial`` (the default) runs them here one after another, ``--backend ray`` as Ray
tasks; the batches are the same, so the files are too, bit for bit. How the work was spread is
printed with the runtime.
"""

from __future__ import annotations

import argparse
import csv
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any, NamedTuple

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from timegap_env.agents.protocol import EVAL_SEED_START
from timegap_env import cli
from timegap_env.config import DEGRADATION_KINDS, DEGRADATIONS, ChartConfig, DegradationConfig, LeaderConfig, PlatoonConfig
from timegap_env.leaders.openacc import default_openacc_dir, openacc_paths, read_openacc, repeated_runs
from timegap_env.leaders.scenarios import make_leader
from timegap_env.monitoring.charts import make_chart
from timegap_env.monitoring.detectors import RecursiveLeastSquares, raw_time_gap
from timegap_env.monitoring.estimate import estimate_time_gap
from timegap_env.monitoring.loop import MonitoredPlatoon
from timegap_env.sim.degradation import parse_degradations, round_to_tick
from timegap_env.config import TIME_GAP_MIN_SPEED
from timegap_env.experiments.backends import Backend, add_arguments

SETTINGS = (1.0, 1.6)  # settings held [s]: the best in nominal episodes and the env's initial one
DURATION = 250.0  # episode length [s]
ONSET = 100.0  # when a degradation starts [s]
WARM_UP = 20.0  # not charted at the start of an episode or a recording [s]
SIZES = (0.0, 0.5, 1.0)  # where in each kind's drawn range its sizes sit [-]
TARGET_FALSE_ALARMS = 2.0  # matched false-alarm rate: excursion starts per follower-hour [1/h]
RLS_FORGETTING = 0.995  # memory about 200 ticks = 20 s [-]
FAMILIES = ("aggressive_cycles", "sinusoid", "hard_braking", "stochastic_human")  # the env's default leaders
CALIBRATION_SEED_START = 2_000  # calibration seeds: training seeds, apart from the held-out ones from EVAL_SEED_START
DETECTORS = {  # name -> (statistic, chart kind)
    "bayes_shewhart": ("bayes", "shewhart"), "bayes_ewma": ("bayes", "ewma"), "bayes_cusum": ("bayes", "cusum"),
    "raw_shewhart": ("raw", "shewhart"), "raw_ewma": ("raw", "ewma"), "rls_shewhart": ("rls", "shewhart"),
}
WIDTH_FIELD = {"shewhart": "limit_width", "ewma": "ewma_width", "cusum": "cusum_h"}  # the threshold of each chart
WIDTH_SEARCH = (0.05, 1e5)  # widths searched, in in-control sigmas of the statistic [-]


class Batch(NamedTuple):
    """A batch of episodes: each detector's statistic per tick and follower, and where charting starts."""

    statistics: dict[str, np.ndarray]  # statistic -> (n_ticks, n_envs, n_followers) [s], finite
    start: int  # first charted tick [-]
    onset: int  # first tick of the degradation [-]


def simulate(setting: float, seeds: Sequence[int], degradation: dict[str, Any] | None) -> Batch:
    """One episode per seed at ``setting`` [s] with ``degradation`` pinned: the detectors' statistics."""
    platoon = PlatoonConfig(initial_setting=setting)
    n_envs, n_followers, dt = len(seeds), platoon.n_followers, platoon.dt
    leaders = [make_leader(FAMILIES[seed % len(FAMILIES)], seed, LeaderConfig(duration=DURATION)) for seed in seeds]
    speed, accel = (np.stack([getattr(leader, name) for leader in leaders], axis=1) for name in ("speed", "accel"))
    loop = MonitoredPlatoon(platoon, n_envs=n_envs)
    loop.sensors.keys[:] = [np.random.default_rng(seed).integers(0, 2**63, dtype=np.uint64) for seed in seeds]
    degradations = parse_degradations(degradation, n_followers)
    for env, seed in enumerate(seeds):
        loop.degrade(env, degradations, key=seed)
    loop.reset(speed[0], accel[0])
    n_ticks = speed.shape[0] - 1
    v2v = loop.degradation.v2v_up(np.broadcast_to(np.arange(n_ticks)[:, None], (n_ticks, n_envs)))
    block = loop.run(speed[1:], accel[1:], v2v)
    readings = block.readings
    raw = raw_time_gap(readings.speed, readings.spacing, platoon.standstill_spacing)
    rls = RecursiveLeastSquares(n_envs, n_followers, setting, forgetting=RLS_FORGETTING,
                                prior_standstill_spacing=platoon.standstill_spacing)
    onset = 0 if degradation is None else round(degradations[0].onset / dt)
    return Batch({"bayes": block.tau_mean, "raw": np.where(np.isnan(raw), setting, raw),
                  "rls": rls.update_block(readings.speed, readings.spacing)}, round(WARM_UP / dt), onset)


class Threshold(NamedTuple):
    """A detector's chart, matched to the target false-alarm rate: centred on setting + offset."""

    offset: float  # in-control mean of the statistic's deviation from the setting on nominal calibration episodes [s]
    sigma: float  # its in-control std [s]
    width: float  # the chart's threshold in those sigmas (Shewhart L, EWMA width, CUSUM h) [-]


def excursion_starts(statistic: np.ndarray, centers: np.ndarray, kind: str, threshold: Threshold) -> np.ndarray:
    """Where a chart of ``kind`` with ``threshold`` starts an excursion, (n_ticks, n_envs, n_followers)."""
    config = ChartConfig(kind=kind, baseline_std=threshold.sigma, **{WIDTH_FIELD[kind]: threshold.width})
    chart = make_chart(statistic.shape[1], statistic.shape[2], centers[0], config)
    return chart.update_block(statistic, centers).exceedance


def false_alarms_per_hour(starts: np.ndarray, dt: float) -> float:
    """Excursion starts per follower-hour charted, ``starts`` (n_ticks, n_envs, n_followers) [1/h]."""
    return float(starts.sum() / (starts.size * dt / 3600.0))


def calibrate(batch: Batch, setting: float, kind: str, statistic: str, dt: float) -> Threshold:
    """The statistic's in-control mean deviation from the setting and sigma on nominal ``batch`` (Phase I), and the
    smallest width in those sigmas with at most TARGET_FALSE_ALARMS per follower-hour on it."""
    values = batch.statistics[statistic][batch.start:]
    offset, sigma = float(np.mean(values - setting)), float(np.std(values - setting))
    centers = np.full_like(values, setting + offset)
    low, high = WIDTH_SEARCH
    for _ in range(40):  # false alarms fall as the width grows: bisect
        middle = np.sqrt(low * high)
        if false_alarms_per_hour(excursion_starts(values, centers, kind, Threshold(offset, sigma, middle)), dt) <= TARGET_FALSE_ALARMS:
            high = middle
        else:
            low = middle
    return Threshold(offset, sigma, float(high))


def charted_starts(batch: Batch, setting: float, detector: str, width: Threshold) -> np.ndarray:
    """``detector``'s excursion starts on ``batch`` after the warm-up, (n_ticks charted, n_envs, n_followers)."""
    statistic, kind = DETECTORS[detector]
    values = batch.statistics[statistic][batch.start:]
    return excursion_starts(values, np.full_like(values, setting + width.offset), kind, width)


def detection_delays(starts: np.ndarray, batch: Batch, dt: float) -> tuple[np.ndarray, int]:
    """Seconds from onset (for a degradation from the start: from the warm-up's end) to each follower's first
    excursion start at or after it, for the followers with one; and the number of followers."""
    after = starts[max(batch.onset - batch.start, 0):]
    after = after.reshape(len(after), -1)
    detected = after.any(axis=0)
    return np.argmax(after, axis=0)[detected] * dt, after.shape[1]


def conditions(config: DegradationConfig) -> dict[str, dict[str, Any]]:
    """Each labelled degradation: every sized kind at SIZES of its range (a signed one positive), the others once."""
    labelled = {}
    for kind in DEGRADATION_KINDS:
        if DEGRADATIONS[kind].range_field is not None:
            low, high = config.size_range(kind)
            for position in SIZES:
                size = low + position * (high - low)
                size = round_to_tick(size, PlatoonConfig.dt) if DEGRADATIONS[kind].whole_ticks else round(size, 3)
                labelled[f"{kind} {size:g}"] = {"kind": kind, "size": size, "onset": ONSET}
        else:
            labelled[kind] = {"kind": kind, "onset": 0.0 if kind == "commercial_acc" else ONSET}
    return labelled


def openacc_statistics(setting_prior: float) -> list[tuple[bool, dict[str, np.ndarray], np.ndarray]]:
    """Per OpenACC run (repeats left out): (ACC on, statistic -> (n_ticks, 1, n_followers), driving mask), for the
    followers with a speed and a spacing; the statistics' priors at ``setting_prior`` [s]."""
    runs = [read_openacc(path) for path in openacc_paths(default_openacc_dir())]
    repeats = repeated_runs(runs)
    found = []
    for run in runs:
        if run.name in repeats:
            continue
        columns = [j for j in range(1, run.n_vehicles) if np.isfinite(run.speed[:, j]).any()
                   and np.isfinite(run.spacing[:, j - 1]).any()]
        if not columns:
            continue
        speed, spacing = run.speed[:, columns], run.spacing[:, [j - 1 for j in columns]]
        with np.errstate(invalid="ignore"):
            driving = (speed >= TIME_GAP_MIN_SPEED) & (spacing > 0)
        bayes = estimate_time_gap(speed, spacing, setting=setting_prior).mean
        raw = raw_time_gap(speed, spacing, PlatoonConfig.standstill_spacing)
        rls = RecursiveLeastSquares(1, len(columns), setting_prior, forgetting=RLS_FORGETTING).update_block(
            speed[:, None], spacing[:, None])[:, 0]
        found.append((run.acc, {"bayes": bayes, "raw": raw, "rls": rls}, driving))
    return found


def openacc_false_alarms(recordings: list, widths: dict[str, Threshold], dt: float) -> dict[tuple[bool, str], float]:
    """Per (ACC on, detector): excursion starts per hour of driving, each follower charted around its own median
    statistic over its driving records (the centre line where it is not driving), after the warm-up."""
    counts: dict[tuple[bool, str], list[float]] = {}
    start = round(WARM_UP / dt)
    for acc, statistics, driving in recordings:
        keep = driving[start:]
        for detector, (statistic, kind) in DETECTORS.items():
            values = statistics[statistic][start:]
            usable = keep & np.isfinite(values)
            if not usable.any(axis=0).all():
                usable_columns = usable.any(axis=0)
                values, usable = values[:, usable_columns], usable[:, usable_columns]
                if values.shape[1] == 0:
                    continue
            centre = np.array([np.median(values[usable[:, i], i]) for i in range(values.shape[1])])
            # the deviation from the follower's own centre, charted around 1 s (a chart's centre must be > 0)
            charted = (np.where(usable, values - centre, 0.0) + 1.0)[:, None]
            starts = excursion_starts(charted, np.ones_like(charted), kind, widths[detector])
            alarms, hours = counts.setdefault((acc, detector), [0.0, 0.0])
            counts[(acc, detector)] = [alarms + float(starts[:, 0][usable].sum()), hours + usable.sum() * dt / 3600.0]
    return {key: alarms / hours for key, (alarms, hours) in counts.items() if hours > 0}


def calibrated_widths(setting: float, seeds: Sequence[int]) -> dict[str, Threshold]:
    """Every detector's chart at ``setting`` [s], matched on nominal calibration episodes ``seeds``: one piece."""
    calibration = simulate(setting, seeds, None)
    return {detector: calibrate(calibration, setting, kind, statistic, PlatoonConfig.dt)
            for detector, (statistic, kind) in DETECTORS.items()}


def condition_rows(setting: float, label: str, degradation: dict[str, Any] | None, seeds: Sequence[int],
                   widths: dict[str, Threshold]) -> list[dict[str, Any]]:
    """One row per detector on held-out episodes ``seeds`` at ``setting`` [s]: its false alarms per hour if
    ``degradation`` is None (nominal), else its detection rate and delays: one piece."""
    batch, dt = simulate(setting, seeds, degradation), PlatoonConfig.dt
    rows = []
    for detector, width in widths.items():
        row = {"setting": setting, "condition": label, "detector": detector, "offset": width.offset,
               "sigma": width.sigma, "width": width.width}
        starts = charted_starts(batch, setting, detector, width)
        if degradation is None:
            row["false_alarms_per_hour"] = false_alarms_per_hour(starts, dt)
        else:
            found, followers = detection_delays(starts, batch, dt)
            row["detection_rate"] = found.size / followers
            if found.size:
                row |= {"mean_delay": float(found.mean()), "median_delay": float(np.median(found)),
                        "p90_delay": float(np.percentile(found, 90))}
        rows.append(row)
    return rows


def openacc_rates(setting: float, widths: dict[str, Threshold]) -> dict[tuple[bool, str], float]:
    """:func:`openacc_false_alarms` of the OpenACC runs with priors at ``setting`` [s]: one piece."""
    return openacc_false_alarms(openacc_statistics(setting), widths, PlatoonConfig.dt)


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m train.detection_benchmark", description=__doc__.split("\n")[0])
    parser.add_argument("--episodes", type=int, default=32, help="episodes per condition (default %(default)s)")
    parser.add_argument("--nominal-episodes", type=int, default=96,
                        help="nominal episodes for calibration and again for the test (default %(default)s)")
    parser.add_argument("--out", type=Path, default=Path("runs/monitoring"), help="output directory")
    add_arguments(parser)
    args = parser.parse_args(argv)
    cli.output_dir(args.out)
    try:
        backend = Backend.from_args(args)
    except ValueError as error:
        parser.error(str(error))
    started = time.perf_counter()
    labelled = conditions(DegradationConfig())
    calibration_seeds = list(range(CALIBRATION_SEED_START, CALIBRATION_SEED_START + args.nominal_episodes))
    if calibration_seeds[-1] >= EVAL_SEED_START:
        raise SystemExit(f"--nominal-episodes {args.nominal_episodes}: calibration seeds would reach the held-out "
                         f"ones ({EVAL_SEED_START} on)")
    test_seeds = list(range(EVAL_SEED_START, EVAL_SEED_START + args.nominal_episodes))
    condition_seeds = list(range(EVAL_SEED_START, EVAL_SEED_START + args.episodes))
    widths = dict(zip(SETTINGS, backend.map(calibrated_widths, [(setting, calibration_seeds) for setting in SETTINGS])))
    spread = {"calibration": backend.describe()}
    pieces = [(setting, label, degradation, seeds, widths[setting]) for setting in SETTINGS
              for label, degradation, seeds in [("nominal", None, test_seeds),
                                                *((label, d, condition_seeds) for label, d in labelled.items())]]
    rows = [row for part in backend.map(condition_rows, pieces) for row in part]
    spread["episodes"] = backend.describe()
    real: dict[float, dict[tuple[bool, str], float]] = {}
    if default_openacc_dir().exists():
        real = dict(zip(SETTINGS, backend.map(openacc_rates, [(setting, widths[setting]) for setting in SETTINGS])))
        spread["OpenACC"] = backend.describe()
        note = f"OpenACC runs from `{default_openacc_dir().name}`."
    else:
        note = f"**OpenACC data not found at {default_openacc_dir()}**: no real nominal driving."
        print(note)
    args.out.mkdir(parents=True, exist_ok=True)
    write_csv(args.out / "detection.csv", rows)
    plot(args.out / "detection.png", rows, list(labelled))
    report = write_report(args.out / "detection.md", args, rows, widths, real, list(labelled), note)
    print(report)
    print(f"Runtime: {time.perf_counter() - started:.0f} s; spread: "
          + "; ".join(f"{stage}: {how}" for stage, how in spread.items()))


FIELDS = ("setting", "condition", "detector", "offset", "sigma", "width", "false_alarms_per_hour", "detection_rate", "mean_delay",
          "median_delay", "p90_delay")


def write_csv(path: Path, rows: list[dict[str, Any]]) -> None:
    """Every (setting, condition, detector): its width and its false alarms or its detection."""
    with open(path, "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=FIELDS)
        writer.writeheader()
        for row in rows:
            writer.writerow({k: (f"{v:.4g}" if isinstance(v, float) else v) for k, v in row.items()})


def write_report(path: Path, args: argparse.Namespace, rows: list[dict[str, Any]], widths: dict[float, dict[str, Threshold]],
                 real: dict[float, dict[tuple[bool, str], float]], labels: list[str], note: str) -> str:
    """detection.md: the matched thresholds and false alarms, then detection per condition, per setting."""
    detectors = list(DETECTORS)
    lines = ["# Detection benchmark (`python -m train.detection_benchmark`)", "",
             f"Simulated episodes of {DURATION:g} s behind the default leader families, the setting held; degradations on "
             f"every follower from {ONSET:g} s (commercial ACC: from the start; its delays count from the end of the "
             f"{WARM_UP:g} s warm-up, which no detector charts). Each statistic is charted around the setting plus its "
             "in-control offset, in its own in-control sigma (mean and std of its deviation from the setting on nominal "
             f"calibration episodes), widths matched on {args.nominal_episodes} nominal "
             f"calibration episodes to at most {TARGET_FALSE_ALARMS:g} false alarms per follower-hour; everything else on "
             f"held-out seeds: {args.nominal_episodes} nominal episodes, {args.episodes} per condition. A cell: detection "
             f"rate (followers with an alarm within the {DURATION - ONSET:g} s after onset) / mean, median delay [s] "
             f"(90th percentile). At the matched rate, false alarms alone would give a detection rate of "
             f"{1 - np.exp(-TARGET_FALSE_ALARMS * (DURATION - ONSET) / 3600):.2f} (Poisson). " + note, "",
             "Caveats: the statistics are strongly autocorrelated from tick to tick (the Bayesian estimate is a sliding "
             "window, the raw gap follows the car's slow gap swings), so the matched EWMA and CUSUM thresholds lie far "
             "beyond their textbook values for independent samples (see the widths); recursive least squares fits s0 "
             "besides the time gap, so a radar bias or a slow drift of the gap goes into its s0, and with the "
             "little speed variation of a platoon its estimate wanders (see its in-control sigma): a weak baseline "
             "here. A radar bias that starts at once shows as a jump in the measured spacing; a slow drift would not.",
             ""]
    by_key = {(row["setting"], row["condition"], row["detector"]): row for row in rows}
    for setting in SETTINGS:
        lines += [f"## Setting {setting:g} s", "",
                  "| | " + " | ".join(detectors) + " |", "|---|" + "---|" * len(detectors),
                  "| in-control offset from the setting [s] | " + " | ".join(f"{widths[setting][d].offset:+.4f}" for d in detectors) + " |",
                  "| in-control sigma [s] | " + " | ".join(f"{widths[setting][d].sigma:.4f}" for d in detectors) + " |",
                  "| width [sigmas] | " + " | ".join(f"{widths[setting][d].width:.2f}" for d in detectors) + " |",
                  "| false alarms per follower-hour, held-out nominal | "
                  + " | ".join(f"{by_key[(setting, 'nominal', d)]['false_alarms_per_hour']:.1f}" for d in detectors) + " |"]
        if setting in real:
            for acc, label in ((True, "OpenACC ACC runs"), (False, "OpenACC, people driving")):
                lines.append(f"| false alarms per hour, {label} | "
                             + " | ".join(f"{real[setting][(acc, d)]:.0f}" if (acc, d) in real[setting] else "–"
                                          for d in detectors) + " |")
        for label in labels:
            cells = []
            for d in detectors:
                row = by_key[(setting, label, d)]
                cells.append(f"{row['detection_rate']:.2f}" + (
                    f" / {row['mean_delay']:.1f}, {row['median_delay']:.1f} ({row['p90_delay']:.0f})"
                    if "median_delay" in row else ""))
            lines.append(f"| {label} | " + " | ".join(cells) + " |")
        rates = {d: np.mean([by_key[(setting, label, d)]["detection_rate"] for label in labels]) for d in detectors}
        lines += ["| mean detection rate | " + " | ".join(f"{rates[d]:.2f}" for d in detectors) + " |", ""]
    lines += ["![detection rates](detection.png)", ""]
    text = "\n".join(lines)
    path.write_text(text)
    return text


def plot(path: Path, rows: list[dict[str, Any]], labels: list[str]) -> None:
    """Detection rate per condition and detector, one panel per setting."""
    fig, axes = plt.subplots(len(SETTINGS), 1, figsize=(13, 4.2 * len(SETTINGS)), sharex=True)
    by_key = {(row["setting"], row["condition"], row["detector"]): row for row in rows}
    x = np.arange(len(labels))
    width = 0.8 / len(DETECTORS)
    for ax, setting in zip(np.atleast_1d(axes), SETTINGS):
        for k, detector in enumerate(DETECTORS):
            ax.bar(x + (k - (len(DETECTORS) - 1) / 2) * width,
                   [by_key[(setting, label, detector)]["detection_rate"] for label in labels], width=width, label=detector)
        ax.set_ylabel("detection rate")
        ax.set_title(f"setting {setting:g} s, false alarms matched to {TARGET_FALSE_ALARMS:g} per follower-hour", fontsize=9)
        ax.grid(axis="y", alpha=0.3)
    axes[-1].set_xticks(x, labels, rotation=45, ha="right", fontsize=8)
    axes[0].legend(fontsize=8, ncol=3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    cli.run(main, "python -m train.detection_benchmark")
