"""Calibrate the follower model to the real commercial ACC cars of OpenACC, report it, and write the presets.

    python -m train.calibrate_openacc [--out results/field] [--presets timegap_env/sim/acc_presets.json]

Data: the ACC runs of ``timegap_env.default_openacc_dir()`` at distance setting ``S`` or ``L``
(``M`` has one run, ``SL`` mixes the two in cars the files do not name), without the runs that
repeat the records of another (``repeated_runs``). Sorted by (setting, name), every other run is a
fit run, the rest are held out: each setting is in both halves. A car's records are cut into
segments of at least ``MIN_SEGMENT`` seconds in which its speed, its predecessor's and the spacing
between them are recorded and the car is following (spacing at most ``FOLLOWING_MAX_SPACING``:
beyond it ACC cars cruise at their set speed and the gap opens, a regime the CTH model does not have).

Per car model, three followers are fitted on the fit runs (``timegap_env.sim.calibration``): the
calibrated follower (T, k_s, k_v, highest command, tau* per setting; s0 the standstill spacing the
fit runs' stopped cars keep), the project's default follower with tau* fitted only, and a constant
time-gap follower (s = s0 + tau v); a fourth, the commercial ACC follower, is the median of the
calibrated cars. Each is then simulated behind the recorded predecessors of the held-out runs.
Writes to ``--out``: ``calibration.md`` (parameters, held-out RMSEs, string stability: the
calibrated models' analytic peak gain beside the measured amplification of speed perturbations
down the real platoons), ``calibration.csv``, ``calibration_rmse.png``, ``calibration_example.png``,
``calibration_stability.png``; and the presets (``timegap_env.sim.presets``) to ``--presets``.
"""

from __future__ import annotations

import argparse
import csv
import time
from collections import defaultdict
from collections.abc import Callable, Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from timegap_env import cli
from timegap_env.config import LeaderConfig, PlatoonConfig
from timegap_env.leaders.openacc import (
    TICK, OpenAccRun, default_openacc_dir, lead_car_speeds, openacc_paths, read_openacc, repeated_runs, standstill_spacings,
    valid_stretches,
)
from timegap_env.leaders.profile import LeaderProfile
from timegap_env.leaders.scenarios import make_leader
from timegap_env.sim.trajectory import simulate
from timegap_env.sim.calibration import (
    BOUNDS, FITTED, SETTING_BOUNDS, FollowerFit, FollowerModel, Segment, fit_constant_time_gap, fit_follower,
    record_segments, simulate_constant_time_gap, simulate_follower,
)
from timegap_env.sim.presets import COMMERCIAL_ACC, PRESETS_PATH, write_presets
from timegap_env.sim.stability import StabilityReport, string_stability

SETTINGS = ("S", "L")  # the distance settings calibrated
MIN_SEGMENT = 30.0  # shortest segment fitted or evaluated [s]
FOLLOWING_MAX_SPACING = 60.0  # records with a larger spacing are not car following [m]
MIN_PERTURBATION = 0.1  # a pair of cars is measured when the predecessor's speed varies at least this much (std) [m/s]
AMPLIFICATION_TOLERANCE = 0.02  # a gain above 1 + this amplifies, analytic and measured alike [-]
MIN_PAIRS = 3  # a measured verdict needs at least this many pairs of cars
CANDIDATES = ("calibrated", "commercial ACC", "default, tau* fitted", "constant time gap")
MEASURES = ("spacing_rmse", "speed_rmse", "dynamics_rmse")
PLATOON_SIZE = 5  # followers in the platoons that try the presets in simulation, as in the paper [-]
DEFAULT = PlatoonConfig()  # the project's follower

Predictor = Callable[[Segment, str], tuple[np.ndarray, np.ndarray]]  # (segment, distance setting) -> spacing, speed


def split_runs(runs: Sequence[OpenAccRun]) -> tuple[list[OpenAccRun], list[OpenAccRun]]:
    """The ACC runs at a calibrated setting, sorted by (setting, name): every other one to fit, the rest held out."""
    chosen = sorted((run for run in runs if run.acc and run.distance_setting in SETTINGS),
                    key=lambda run: (run.distance_setting, run.name))
    return chosen[::2], chosen[1::2]


def experiment(run: OpenAccRun) -> str:
    """The campaign's experiment a run belongs to: "dynamic" (speed oscillations around a cruise speed) or
    "handling" (stops, starts and hard accelerations), from its file name."""
    return "dynamic" if "dynamic" in run.name else "handling"


def following_spacing(run: OpenAccRun, j: int) -> np.ndarray:
    """Car j's recorded spacing [m] where it is car following (at most FOLLOWING_MAX_SPACING), NaN elsewhere."""
    spacing = run.spacing[:, j - 1]
    return np.where(spacing <= FOLLOWING_MAX_SPACING, spacing, np.nan)


def car_segments(runs: Sequence[OpenAccRun]) -> dict[str, list[tuple[Segment, str, str]]]:
    """Per car model, its car-following segments in ``runs`` with their distance setting and experiment."""
    segments: dict[str, list[tuple[Segment, str, str]]] = defaultdict(list)
    for run in runs:
        for j in range(1, run.n_vehicles):
            for segment in record_segments(run.speed[:, j], run.speed[:, j - 1], following_spacing(run, j), TICK, MIN_SEGMENT):
                segments[run.vehicles[j]].append((segment, run.distance_setting, experiment(run)))
    return segments


def measured_standstill_spacing(runs: Sequence[OpenAccRun]) -> tuple[float, int]:
    """The median standstill spacing [m] over the stopped follower-runs of ``runs``, and how many there were."""
    spacings = [value for run in runs for _, value in standstill_spacings(run)]
    return float(np.median(spacings)), len(spacings)


def prediction_errors(items: Sequence[tuple[Segment, str, dict[str, Predictor]]]) -> dict[str, dict[str, float]]:
    """Per candidate: spacing RMSE [m], speed RMSE [m/s], and the spacing RMSE once each segment's mean error is
    removed [m] (the dynamics alone), over every record of the (segment, distance setting, predictors) items."""
    errors = {}
    for candidate in CANDIDATES:
        spacing, speed, centred = [], [], []
        for segment, distance_setting, predictors in items:
            simulated_spacing, simulated_speed = predictors[candidate](segment, distance_setting)
            spacing.append(simulated_spacing - segment.spacing)
            centred.append(spacing[-1] - spacing[-1].mean())
            speed.append(simulated_speed - segment.speed)
        errors[candidate] = {"spacing_rmse": _rms(spacing), "speed_rmse": _rms(speed), "dynamics_rmse": _rms(centred)}
    return errors


def _rms(parts: list[np.ndarray]) -> float:
    return float(np.sqrt(np.mean(np.concatenate(parts) ** 2)))


def follower_predictor(fit: FollowerFit, base: PlatoonConfig) -> Predictor:
    """The fitted follower simulated at the segment's distance setting."""
    return lambda segment, distance_setting: simulate_follower(segment, fit.model, fit.settings[distance_setting], base)


def commercial_acc(fits: dict[str, FollowerFit], segments: dict[str, list[tuple[Segment, str, str]]],
                   base: PlatoonConfig) -> FollowerFit:
    """The median car: each fitted parameter and each setting's tau* the median over the car models' fits, scored on
    all their fit segments."""
    model = FollowerModel(*(float(np.median([fit.model[i] for fit in fits.values()])) for i in range(len(FollowerModel._fields))))
    settings = {setting: float(np.median([fit.settings[setting] for fit in fits.values() if setting in fit.settings]))
                for setting in SETTINGS}
    median = FollowerFit(model, settings, spacing_rmse=0.0, n_segments=0, duration=0.0)
    items = [(segment, setting) for car in fits for segment, setting, _ in segments[car]]
    errors = [simulate_follower(segment, model, settings[setting], base)[0] - segment.spacing for segment, setting in items]
    return FollowerFit(model, settings, spacing_rmse=_rms(errors), n_segments=len(items),
                       duration=sum(segment.speed.size - 1 for segment, _ in items) * TICK) if items else median


def amplification(runs: Sequence[OpenAccRun]) -> dict[tuple[str, str], list[float]]:
    """Per (car model, setting): the measured amplification of speed perturbations by that car, one value per pair
    of consecutive cars of a run: std(follower's speed) / std(predecessor's speed) over their car-following records
    (stretches of at least MIN_SEGMENT with both speeds and the spacing recorded; std about each stretch's mean),
    for pairs whose predecessor's speed varied by at least MIN_PERTURBATION."""
    ratios: dict[tuple[str, str], list[float]] = defaultdict(list)
    for run in runs:
        for j in range(1, run.n_vehicles):
            recorded = np.isfinite(run.speed[:, j]) & np.isfinite(run.speed[:, j - 1]) & np.isfinite(following_spacing(run, j))
            stretches = [(start, end) for start, end in valid_stretches(recorded) if (end - start - 1) * TICK >= MIN_SEGMENT]
            if not stretches:
                continue
            follower, predecessor = (np.concatenate([speed[start:end] - speed[start:end].mean() for start, end in stretches])
                                     for speed in (run.speed[:, j], run.speed[:, j - 1]))
            if predecessor.std() >= MIN_PERTURBATION:
                ratios[run.vehicles[j], run.distance_setting].append(float(follower.std() / predecessor.std()))
    return ratios


def stability(model: FollowerModel, setting: float) -> StabilityReport:
    """The analytic string stability of ``model`` in ACC at ``setting`` tau* [s] (gain 1, k_a of DEFAULT)."""
    return string_stability(k_s=model.k_s, k_v=model.k_v, k_a=DEFAULT.k_a, k_f=0.0, setting=setting, lag=model.lag,
                            gain=1.0, delay=0.0)


def amplifies(gain: float) -> bool:
    """A gain [-] (analytic peak or measured ratio) that amplifies perturbations, beyond AMPLIFICATION_TOLERANCE."""
    return gain > 1.0 + AMPLIFICATION_TOLERANCE


def collisions(presets: dict[str, FollowerFit], leaders: dict[str, list[LeaderProfile]]) -> dict[tuple[str, str], dict[str, int]]:
    """Per (car model, distance setting): how many of each group of ``leaders`` a PLATOON_SIZE platoon of the preset
    collides behind."""
    return {(car, setting): {group: sum(simulate(profile, fit.platoon_config(setting, n_followers=PLATOON_SIZE)).collision
                                        is not None for profile in profiles) for group, profiles in leaders.items()}
            for car, fit in presets.items() for setting in SETTINGS}


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m train.calibrate_openacc", description=__doc__.split("\n")[0])
    parser.add_argument("--out", type=Path, default=Path("runs/field"), help="report directory (default %(default)s)")
    parser.add_argument("--presets", type=Path, help="where the presets go (default: the package's; none with --cars)")
    parser.add_argument("--cars", nargs="+", metavar="CAR", help="calibrate only these car models (default: all)")
    args = parser.parse_args(argv)
    cli.output_dir(args.out)
    if args.presets is not None:
        cli.output_file(args.presets, "--presets")
    directory = default_openacc_dir()
    if not directory.exists():
        raise SystemExit(f"OpenACC data not found at {directory}: set $TIMEGAP_OPENACC_PATH to a directory of OpenACC files")
    started = time.perf_counter()
    runs = [read_openacc(path) for path in openacc_paths(directory)]
    repeats = repeated_runs(runs)  # a run cut out of another: fitting one and holding out the other would leak
    fit_runs, held_out_runs = split_runs([run for run in runs if run.name not in repeats])
    standstill = measured_standstill_spacing(fit_runs)
    base = DEFAULT.with_overrides({"standstill_spacing": standstill[0]})  # the calibrated followers' s0
    fit_segments, test_segments = car_segments(fit_runs), car_segments(held_out_runs)
    settings_in = {name: {car: {setting for _, setting, _ in items} for car, items in found.items()}
                   for name, found in (("fit", fit_segments), ("test", test_segments))}
    cars = sorted(car for car in fit_segments if settings_in["fit"][car] & settings_in["test"].get(car, set())
                  and (args.cars is None or car in args.cars))

    rows = []
    for car in cars:
        segments, settings, _ = zip(*fit_segments[car])
        rows.append({"car": car, "fit": fit_follower(segments, settings, base),
                     "default": fit_follower(segments, settings, DEFAULT, free=False),
                     "constant": fit_constant_time_gap(segments, settings, TICK)})
    fits = {row["car"]: row["fit"] for row in rows}
    median = commercial_acc(fits, fit_segments, base)
    pooled: dict[str, list] = {"dynamic": [], "handling": []}  # held-out (segment, setting, predictors) by experiment
    for row in rows:
        s0, taus = row["constant"]
        predictors = {
            "calibrated": follower_predictor(row["fit"], base),
            "commercial ACC": follower_predictor(median, base),
            "default, tau* fitted": follower_predictor(row["default"], DEFAULT),
            "constant time gap": lambda segment, setting, s0=s0, taus=taus: simulate_constant_time_gap(segment, taus[setting], s0, TICK),
        }
        held_out = [(segment, setting, kind) for segment, setting, kind in test_segments[row["car"]] if setting in row["fit"].settings]
        row["errors"] = prediction_errors([(segment, setting, predictors) for segment, setting, _ in held_out])
        row["held_out"] = (len(held_out), sum(segment.speed.size - 1 for segment, *_ in held_out) * TICK)
        for segment, setting, kind in held_out:
            pooled[kind].append((segment, setting, predictors))
    by_experiment = {kind: prediction_errors(items) for kind, items in pooled.items() if items}
    fitting_time = time.perf_counter() - started
    presets = args.presets or (PRESETS_PATH if args.cars is None else None)  # a subset never overwrites the package's
    if presets is not None:
        write_presets(presets, {**fits, COMMERCIAL_ACC: median},
                      source=f"python -m train.calibrate_openacc, fit runs: {', '.join(run.name for run in fit_runs)}")

    measured = amplification(fit_runs + held_out_runs)
    leaders = {"the paper's leader": [make_leader("paper", seed=0)],
               "OpenACC lead cars": [LeaderProfile.from_speed(np.maximum(speed, 0.0), TICK, name=name)
                                     for name, speed in lead_car_speeds(directory)
                                     if name not in repeats and speed.size * TICK >= LeaderConfig().min_recorded_duration]}
    crashes = collisions({**fits, COMMERCIAL_ACC: median}, leaders)
    args.out.mkdir(parents=True, exist_ok=True)
    write_csv(args.out / "calibration.csv", rows)
    plot_rmse(args.out / "calibration_rmse.png", rows)
    plot_example(args.out / "calibration_example.png", rows, test_segments, base)
    plot_stability(args.out / "calibration_stability.png", fits, measured)
    report = write_report(args.out / "calibration.md", rows, by_experiment, median, measured, fit_runs, held_out_runs,
                          repeats, standstill, crashes, leaders)
    print(report)
    written = f"Presets written to {presets}." if presets else "No presets written (--cars without --presets)."
    print(f"Runtime: {fitting_time:.0f} s for the fits, {time.perf_counter() - started:.0f} s in all. {written}")


def write_csv(path: Path, rows: list[dict]) -> None:
    """One row per car model: fitted parameters, and every candidate's held-out errors."""
    with open(path, "w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(["car", *FollowerModel._fields, *(f"tau_{s}" for s in SETTINGS), "fit_spacing_rmse",
                         "held_out_segments", "held_out_seconds",
                         *(f"{candidate}: {measure}" for candidate in CANDIDATES for measure in MEASURES)])
        for row in rows:
            fit = row["fit"]
            writer.writerow([row["car"], *(f"{value:.4g}" for value in fit.model),
                             *(f"{fit.settings[s]:.4g}" if s in fit.settings else "" for s in SETTINGS),
                             f"{fit.spacing_rmse:.4g}", row["held_out"][0], f"{row['held_out'][1]:.0f}",
                             *(f"{row['errors'][candidate][measure]:.4g}" for candidate in CANDIDATES for measure in MEASURES)])


def plot_rmse(path: Path, rows: list[dict]) -> None:
    """Held-out spacing RMSE, its dynamics part, and speed RMSE per car model, the candidates side by side."""
    fig, axes = plt.subplots(1, 3, figsize=(15, 5.5), sharey=True)
    y = np.arange(len(rows))
    height = 0.8 / len(CANDIDATES)
    labels = {"spacing_rmse": "spacing RMSE [m]", "dynamics_rmse": "spacing RMSE, each segment's mean error removed [m]",
              "speed_rmse": "speed RMSE [m/s]"}
    for ax, measure in zip(axes, ("spacing_rmse", "dynamics_rmse", "speed_rmse")):
        for k, candidate in enumerate(CANDIDATES):
            ax.barh(y + (k - (len(CANDIDATES) - 1) / 2) * height, [row["errors"][candidate][measure] for row in rows],
                    height=height, label=candidate)
        ax.set_xlabel(labels[measure], fontsize=9)
        ax.grid(axis="x", alpha=0.3)
    axes[0].set_yticks(y, [row["car"] for row in rows], fontsize=8)
    axes[0].legend(fontsize=8)
    fig.suptitle("Held-out OpenACC runs: each follower simulated behind the recorded predecessors", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_example(path: Path, rows: list[dict], test_segments: dict[str, list[tuple[Segment, str, str]]],
                 base: PlatoonConfig) -> None:
    """For four car models, their longest held-out segment: recorded spacing and the calibrated follower's."""
    chosen = sorted(rows, key=lambda row: -row["held_out"][1])[:4]
    fig, axes = plt.subplots(len(chosen), 1, figsize=(10, 2.4 * len(chosen)), squeeze=False)
    for ax, row in zip(axes[:, 0], chosen):
        fit = row["fit"]
        segment, setting = max(((s, t) for s, t, _ in test_segments[row["car"]] if t in fit.settings),
                               key=lambda st: st[0].speed.size)
        t = np.arange(segment.speed.size) * TICK
        simulated, _ = simulate_follower(segment, fit.model, fit.settings[setting], base)
        ax.plot(t, segment.spacing, color="k", lw=1, label="recorded")
        ax.plot(t, simulated, color="C0", lw=1, label="calibrated follower")
        ax.set_ylabel("spacing [m]")
        ax.set_title(f"{row['car']}, setting {setting}", fontsize=9)
        ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=8)
    axes[-1, 0].set_xlabel("time into the segment [s]")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_stability(path: Path, fits: dict[str, FollowerFit], measured: dict[tuple[str, str], list[float]]) -> None:
    """Analytic peak gain of each calibrated car model beside its measured amplification (median over at least
    MIN_PAIRS pairs), per setting; the shaded band is AMPLIFICATION_TOLERANCE."""
    fig, ax = plt.subplots(figsize=(6.5, 5))
    for k, setting in enumerate(SETTINGS):
        points = [(stability(fit.model, fit.settings[setting]).peak_gain, float(np.median(measured[car, setting])))
                  for car, fit in fits.items() if setting in fit.settings and len(measured.get((car, setting), [])) >= MIN_PAIRS]
        if points:
            ax.scatter(*zip(*points), color=f"C{k}", label=f"setting {setting}")
    for line in (ax.axvline, ax.axhline):
        line(1.0, color="0.5", lw=0.8)
    ax.axvspan(1.0, 1.0 + AMPLIFICATION_TOLERANCE, color="0.9")
    ax.axhspan(1.0 - AMPLIFICATION_TOLERANCE, 1.0 + AMPLIFICATION_TOLERANCE, color="0.9")
    ax.set_xlabel("calibrated model: max |G(jω)|")
    ax.set_ylabel("measured: median std(v_follower) / std(v_predecessor)")
    ax.set_title("String stability: model against the real platoons", fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def write_report(
    path: Path, rows: list[dict], by_experiment: dict[str, dict[str, dict[str, float]]], median: FollowerFit,
    measured: dict[tuple[str, str], list[float]], fit_runs: list[OpenAccRun], held_out_runs: list[OpenAccRun],
    repeats: dict[str, str], standstill: tuple[float, int], crashes: dict[tuple[str, str], dict[str, int]],
    leaders: dict[str, list[LeaderProfile]],
) -> str:
    """calibration.md: the method, parameters, held-out errors and string stability; returns its text."""
    fitted = ", ".join(FITTED)
    lines = [
        "# Follower model calibrated to real commercial ACC cars (`python -m train.calibrate_openacc`)", "",
        f"Data: the OpenACC AstaZero runs (`timegap_env.default_openacc_dir()`): the {len(fit_runs) + len(held_out_runs)} "
        f"ACC runs at setting S or L, sorted by (setting, name), every other one fitted ({len(fit_runs)}), the rest held "
        f"out ({len(held_out_runs)})" + "".join(f"; `{a}` repeats records of `{b}` and is left out" for a, b in repeats.items())
        + f". Segments: at least {MIN_SEGMENT:g} s with the car's speed, its predecessor's and the spacing recorded and "
        f"the spacing at most {FOLLOWING_MAX_SPACING:g} m (beyond it ACC cars cruise at their set speed and the gap "
        "opens: no car following to fit). Each follower is simulated behind the recorded predecessor from the segment's "
        "first record (the predecessor's position: the car's integrated speed plus the recorded spacing) and fitted by "
        "least squares on the spacing error (`timegap_env.sim.calibration`).", "",
        f"Candidates: **calibrated** = GLVD + CTH in ACC with {fitted} and tau* per setting fitted per car model; "
        f"K = 1 and k_a = {DEFAULT.k_a} held (spacing and speed cannot tell K from the gains nor k_a from T); s0 = "
        f"{standstill[0]:.2f} m for every car, the median spacing of the fit runs' {standstill[1]} stopped "
        "follower-runs (held: fitted freely, s0 trades off against tau* where a car's speed hardly varies, and ran to 13 m "
        f"with tau* at its bound); the lowest command held at {DEFAULT.accel_min:g} m/s² (ACC driving seldom brakes at the "
        "car's limit, so the records do not reveal it). **commercial ACC** = the median of the calibrated cars, "
        "parameter by parameter. **default, tau* fitted** = the project's follower "
        f"(T = {DEFAULT.actuation_lag} s, k_s = {DEFAULT.k_s}, k_v = {DEFAULT.k_v}, s0 = {DEFAULT.standstill_spacing:g} m) "
        "with only tau* fitted. **constant time gap** = a follower that always keeps s = s0 + tau v (tau, s0 fitted).", "",
        "The fits write the presets `timegap_env.acc_presets()` reads (`timegap_env/sim/acc_presets.json`).", "",
        "## Fitted parameters (fit runs)", "",
        "| car | T [s] | k_s [1/s²] | k_v [1/s] | highest command [m/s²] | τ* S [s] | τ* L [s] | fit spacing RMSE [m] (default follower's) | segments, duration |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for row in rows:
        fit, default = row["fit"], row["default"]
        lines.append(f"| {row['car']} | {_parameters(fit)} | {fit.spacing_rmse:.2f} ({default.spacing_rmse:.2f}) | "
                     f"{fit.n_segments}, {fit.duration:.0f} s |")
    lines += [f"| **{COMMERCIAL_ACC}** (median) | {_parameters(median)} | {median.spacing_rmse:.2f} (all cars' segments) | "
              f"{median.n_segments}, {median.duration:.0f} s |", "",
              "`*`: the fit sits at the parameter's bound (`timegap_env.sim.calibration.BOUNDS`, `SETTING_BOUNDS`): the "
              "records do not pin it down inside them.", "",
              "## Held-out runs: spacing RMSE [m] / speed RMSE [m/s] (spacing RMSE with each segment's mean error removed)", "",
              "| car | held-out segments, duration | " + " | ".join(CANDIDATES) + " |", "|---|---|" + "---|" * len(CANDIDATES)]
    for row in rows:
        lines.append(f"| {row['car']} | {row['held_out'][0]}, {row['held_out'][1]:.0f} s | {_errors(row['errors'])} |")
    wins = {candidate: sum(row["errors"][candidate]["spacing_rmse"] == min(row["errors"][c]["spacing_rmse"] for c in CANDIDATES)
                           for row in rows) for candidate in CANDIDATES}
    lines += ["", "Lowest held-out spacing RMSE: " + ", ".join(f"{candidate} {count} of {len(rows)} cars"
                                                               for candidate, count in wins.items()) + ".",
              "", "Pooled over the cars, by experiment (dynamic: speed oscillations around a cruise speed; handling: stops, "
              "starts, hard accelerations):", "", "| experiment | " + " | ".join(CANDIDATES) + " |", "|---|" + "---|" * len(CANDIDATES)]
    for kind, errors in by_experiment.items():
        lines.append(f"| {kind} | {_errors(errors)} |")
    lines += [
        "", "![held-out errors](calibration_rmse.png)", "![a held-out segment per car](calibration_example.png)", "",
        "## String stability: the calibrated models against the real platoons", "",
        "Analytic: max_ω |G(jω)| of the calibrated model at the setting's τ* (ACC, no V2V). Measured: for every pair of "
        "consecutive cars of a run, std(follower's speed) / std(predecessor's speed) over their car-following records "
        f"(stretches of at least {MIN_SEGMENT:g} s with both speeds and the spacing recorded, the spacing at most "
        f"{FOLLOWING_MAX_SPACING:g} m; deviations from each stretch's mean), for pairs whose predecessor's speed varied "
        f"by at least {MIN_PERTURBATION:g} m/s (std): the amplification of the perturbations the car received, all "
        "frequencies together, where the analytic peak is the worst frequency. A gain amplifies above "
        f"1 + {AMPLIFICATION_TOLERANCE:g}, on both sides; the measured verdict is the median's, over at least "
        f"{MIN_PAIRS} pairs.", "",
        "| car | setting | peak gain, calibrated | peak gain, default τ* fitted | measured amplification: median [min, max] | pairs amplifying | verdicts |",
        "|---|---|---|---|---|---|---|"]
    counts = {"agree": 0, "disagree": 0, f"fewer than {MIN_PAIRS} pairs": 0}
    for row in rows:
        for setting in SETTINGS:
            values = measured.get((row["car"], setting), [])
            if setting not in row["fit"].settings or not values:
                continue
            analytic = stability(row["fit"].model, row["fit"].settings[setting]).peak_gain
            default = stability(row["default"].model, row["default"].settings[setting]).peak_gain
            typical = float(np.median(values))
            if len(values) < MIN_PAIRS:
                verdict = f"fewer than {MIN_PAIRS} pairs"
            else:
                verdict = "agree" if amplifies(analytic) == amplifies(typical) else "disagree"
            counts[verdict] += 1
            lines.append(f"| {row['car']} | {setting} | {analytic:.3f} | {default:.3f} | {typical:.3f} "
                         f"[{min(values):.2f}, {max(values):.2f}] | {sum(amplifies(v) for v in values)}/{len(values)} | {verdict} |")
    unstable = [row["car"] for row in rows if "S" in row["fit"].settings and amplifies(stability(row["fit"].model, row["fit"].settings["S"]).peak_gain)]
    lines += ["", f"The calibrated model's verdict (amplifies or not) agrees with the measured one in {counts['agree']} of "
              f"{counts['agree'] + counts['disagree']} car-settings with at least {MIN_PAIRS} pairs "
              f"({counts[f'fewer than {MIN_PAIRS} pairs']} with fewer). Calibrated models string unstable at S: "
              f"{len(unstable)} of {sum('S' in row['fit'].settings for row in rows)} cars.", "",
              "![stability](calibration_stability.png)", "",
              "## The presets in simulation", "",
              f"Each preset (`acc_platoon(car, setting, n_followers={PLATOON_SIZE})`) simulated behind "
              + " and ".join(f"{group} ({len(profiles)})" for group, profiles in leaders.items())
              + ": platoons that collide (a gap reaches 0; the run stops there).", "",
              "| car | " + " | ".join(f"{group}, {setting}" for setting in SETTINGS for group in leaders) + " |",
              "|---|" + "---|" * (len(SETTINGS) * len(leaders))]
    for car in sorted({car for car, _ in crashes}):
        lines.append(f"| {car} | " + " | ".join(f"{crashes[car, setting][group]}/{len(leaders[group])}"
                                                for setting in SETTINGS for group in leaders) + " |")
    lines.append("")
    text = "\n".join(lines)
    path.write_text(text)
    return text


def _parameters(fit: FollowerFit) -> str:
    """The fitted parameters as table cells, each starred at a bound of the fit."""
    digits = {"lag": 2, "k_s": 3, "k_v": 2, "accel_max": 1}
    cells = [_starred(getattr(fit.model, name), BOUNDS[name], digits[name]) for name in FITTED]
    cells += [_starred(fit.settings[setting], SETTING_BOUNDS, 2) if setting in fit.settings else "–" for setting in SETTINGS]
    return " | ".join(cells)


def _starred(value: float, bounds: tuple[float, float], digits: int) -> str:
    """``value`` with ``digits`` decimals, starred when it sits at one of ``bounds``."""
    return f"{value:.{digits}f}" + ("*" if min(abs(value - bound) for bound in bounds) < 1e-6 else "")


def _errors(errors: dict[str, dict[str, float]]) -> str:
    """Every candidate's held-out errors as table cells."""
    return " | ".join(f"{errors[c]['spacing_rmse']:.2f} / {errors[c]['speed_rmse']:.2f} ({errors[c]['dynamics_rmse']:.2f})"
                      for c in CANDIDATES)


if __name__ == "__main__":
    cli.run(main, "python -m train.calibrate_openacc")
