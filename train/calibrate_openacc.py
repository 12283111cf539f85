"""Calibrate the follower model to the real commercial ACC cars of OpenACC, report it, and write the presets.

    python -m train.calibrate_openacc [--out results/field] [--presets timegap_env/sim/acc_presets.json]

Data: the ACC runs of ``timegap_env.default_openacc_dir()`` at distance setting ``S`` or ``L``
(``M`` has one run, ``SL`` mixes the two in cars the files do not name), without the runs that
repeat the records of another (``repeated_runs``). Sorted by (setting, name),
every other run is a fit run, the rest are held out: each setting is in both halves. A car's
records are cut into segments of at least ``MIN_SEGMENT`` seconds in which its speed, its
predecessor's and the spacing between them are recorded and the car is following (spacing at
most ``FOLLOWING_MAX_SPACING``: beyond it ACC cars cruise at their set speed and the gap opens,
a regime the CTH model does not have).

Per car model, three followers are fitted on the fit runs (``timegap_env.sim.calibration``): the
calibrated follower (T, k_s, k_v, s0, command bounds, tau* per setting), the project's default
follower with tau* fitted only, and a constant time-gap follower (s = s0 + tau v); each is then
simulated behind the recorded predecessors of the held-out runs. Writes to ``--out``:
``calibration.md`` (parameters, held-out RMSEs, string stability: the calibrated models' analytic
peak gain beside the measured amplification of speed perturbations down the real platoons),
``calibration.csv``, ``calibration_rmse.png``, ``calibration_example.png``, ``calibration_stability.png``;
and the presets (``timegap_env.sim.presets``: the calibrated follower of each car model and their
median, the "commercial ACC" follower) to ``--presets``.
"""

from __future__ import annotations

import argparse
import csv
import json
import time
from collections import defaultdict
from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from timegap_env.config import PlatoonConfig
from timegap_env.leaders.openacc import OpenAccRun, default_openacc_dir, openacc_paths, read_openacc, repeated_runs
from timegap_env.sim.calibration import (
    BOUNDS, SETTING_BOUNDS, FollowerFit, FollowerModel, Segment, fit_constant_time_gap, fit_follower, record_segments,
    simulate_constant_time_gap, simulate_follower,
)
from timegap_env.sim.presets import COMMERCIAL_ACC, PRESETS_PATH, write_presets
from timegap_env.sim.stability import StabilityReport, string_stability

SETTINGS = ("S", "L")  # the distance settings calibrated
MIN_SEGMENT = 30.0  # shortest segment fitted or evaluated [s]
FOLLOWING_MAX_SPACING = 60.0  # records with a larger spacing are not car following [m]
STABILITY_MIN_OVERLAP = 30.0  # a pair of cars needs this much time with both speeds recorded [s]
MODELS = ("calibrated", "default, tau* fitted", "constant time gap")
BASE = PlatoonConfig()


def split_runs(runs: Sequence[OpenAccRun]) -> tuple[list[OpenAccRun], list[OpenAccRun]]:
    """The ACC runs at a calibrated setting, sorted by (setting, name): every other one to fit, the rest held out."""
    chosen = sorted((run for run in runs if run.acc and run.distance_setting in SETTINGS),
                    key=lambda run: (run.distance_setting, run.name))
    return chosen[::2], chosen[1::2]


def experiment(run: OpenAccRun) -> str:
    """The campaign's experiment a run belongs to: "dynamic" (speed oscillations around a cruise speed) or
    "handling" (stops, starts and hard accelerations), from its file name."""
    return "dynamic" if "dynamic" in run.name else "handling"


def car_segments(runs: Sequence[OpenAccRun]) -> dict[str, list[tuple[Segment, str, str]]]:
    """Per car model, its car-following segments in ``runs`` with their distance setting and experiment."""
    segments: dict[str, list[tuple[Segment, str, str]]] = defaultdict(list)
    for run in runs:
        dt = float(np.round(run.t[1] - run.t[0], 6))
        for j in range(1, run.n_vehicles):
            spacing = np.where(run.spacing[:, j - 1] <= FOLLOWING_MAX_SPACING, run.spacing[:, j - 1], np.nan)
            for segment in record_segments(run.speed[:, j], run.speed[:, j - 1], spacing, dt, MIN_SEGMENT):
                segments[run.vehicles[j]].append((segment, run.distance_setting, experiment(run)))
    return segments


def held_out_errors(
    segments: Sequence[tuple[Segment, str]], predict: dict[str, object]
) -> dict[str, dict[str, float]]:
    """Per model: spacing RMSE [m], speed RMSE [m/s], and the spacing RMSE once each segment's mean error is
    removed [m] (the dynamics alone), over every record of ``segments``."""
    errors = {}
    for name, simulate in predict.items():
        spacing, speed, centred = [], [], []
        for segment, setting in segments:
            simulated_spacing, simulated_speed = simulate(segment, setting)
            spacing_error = simulated_spacing - segment.spacing
            spacing.append(spacing_error)
            centred.append(spacing_error - spacing_error.mean())
            speed.append(simulated_speed - segment.speed)
        errors[name] = {"spacing_rmse": _rms(spacing), "speed_rmse": _rms(speed), "dynamics_rmse": _rms(centred)}
    return errors


def pooled_errors(items: list[tuple[Segment, str, dict]]) -> dict[str, dict[str, float]]:
    """:func:`held_out_errors` over segments of several cars, each simulated with its own car's models."""
    errors = {}
    for model in MODELS:
        spacing, speed, centred = [], [], []
        for segment, setting, predict in items:
            simulated_spacing, simulated_speed = predict[model](segment, setting)
            spacing.append(simulated_spacing - segment.spacing)
            centred.append(spacing[-1] - spacing[-1].mean())
            speed.append(simulated_speed - segment.speed)
        errors[model] = {"spacing_rmse": _rms(spacing), "speed_rmse": _rms(speed), "dynamics_rmse": _rms(centred)}
    return errors


def _rms(parts: list[np.ndarray]) -> float:
    return float(np.sqrt(np.mean(np.concatenate(parts) ** 2)))


def amplification(runs: Sequence[OpenAccRun]) -> dict[tuple[str, str], list[float]]:
    """Per (car model, setting): the measured amplification of speed perturbations by that car, one value per pair
    of consecutive recorded cars of a run, std(follower's speed) / std(predecessor's speed) over their common records."""
    ratios: dict[tuple[str, str], list[float]] = defaultdict(list)
    for run in runs:
        dt = float(np.round(run.t[1] - run.t[0], 6))
        for j in range(1, run.n_vehicles):
            both = np.isfinite(run.speed[:, j]) & np.isfinite(run.speed[:, j - 1])
            if both.sum() * dt < STABILITY_MIN_OVERLAP:
                continue
            follower, predecessor = run.speed[both, j], run.speed[both, j - 1]
            ratios[run.vehicles[j], run.distance_setting].append(float(follower.std() / predecessor.std()))
    return ratios


def stability(model: FollowerModel, setting: float) -> StabilityReport:
    """The analytic string stability of ``model`` in ACC at ``setting`` tau* [s] (gain 1, k_a of BASE)."""
    return string_stability(k_s=model.k_s, k_v=model.k_v, k_a=BASE.k_a, k_f=0.0, setting=setting, lag=model.lag,
                            gain=1.0, delay=0.0)


def commercial_acc(fits: dict[str, FollowerFit]) -> FollowerFit:
    """The median car: each parameter and each setting's tau* the median over the car models."""
    model = FollowerModel(*(float(np.median([fit.model[i] for fit in fits.values()])) for i in range(len(FollowerModel._fields))))
    settings = {setting: float(np.median([fit.settings[setting] for fit in fits.values() if setting in fit.settings]))
                for setting in SETTINGS}
    return FollowerFit(model, settings, spacing_rmse=float("nan"), n_segments=sum(fit.n_segments for fit in fits.values()),
                       duration=sum(fit.duration for fit in fits.values()))


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m train.calibrate_openacc", description=__doc__.split("\n")[0])
    parser.add_argument("--out", type=Path, default=Path("results/field"), help="report directory (default %(default)s)")
    parser.add_argument("--presets", type=Path, help="where the presets go (default: the package's; none with --cars)")
    parser.add_argument("--cars", nargs="+", metavar="CAR", help="calibrate only these car models (default: all)")
    args = parser.parse_args(argv)
    directory = default_openacc_dir()
    if not directory.exists():
        raise SystemExit(f"OpenACC data not found at {directory}: set $TIMEGAP_OPENACC_PATH to a directory of OpenACC files")
    started = time.perf_counter()
    runs = [read_openacc(path) for path in openacc_paths(directory)]
    repeats = repeated_runs(runs)  # a run cut out of another: fitting one and holding out the other would leak
    fit_runs, held_out_runs = split_runs([run for run in runs if run.name not in repeats])
    fit_segments, test_segments = car_segments(fit_runs), car_segments(held_out_runs)
    cars = sorted(car for car in fit_segments if car in test_segments and (args.cars is None or car in args.cars))

    fits: dict[str, FollowerFit] = {}
    rows = []
    pooled: dict[str, list] = {"dynamic": [], "handling": []}  # held-out (segment, setting, the car's models) by experiment
    for car in cars:
        segments, settings, _ = zip(*fit_segments[car])
        fits[car] = fit = fit_follower(segments, settings, BASE)
        default = fit_follower(segments, settings, BASE, free=False)
        constant_s0, constant_settings = fit_constant_time_gap(segments, settings, BASE.dt)
        held_out = [(segment, setting, kind) for segment, setting, kind in test_segments[car] if setting in fit.settings]
        predict = {
            MODELS[0]: lambda segment, setting, fit=fit: simulate_follower(segment, fit.model, fit.settings[setting], BASE),
            MODELS[1]: lambda segment, setting, fit=default: simulate_follower(segment, fit.model, fit.settings[setting], BASE),
            MODELS[2]: lambda segment, setting, s0=constant_s0, taus=constant_settings: simulate_constant_time_gap(
                segment, taus[setting], s0, BASE.dt),
        }
        errors = held_out_errors([(segment, setting) for segment, setting, _ in held_out], predict)
        for kind in ("dynamic", "handling"):
            pooled[kind].extend((segment, setting, predict) for segment, setting, k in held_out if k == kind)
        rows.append({"car": car, "fit": fit, "default": default, "errors": errors,
                     "held_out": (len(held_out), sum(segment.speed.size - 1 for segment, *_ in held_out) * BASE.dt)})
    by_experiment = {kind: pooled_errors(items) for kind, items in pooled.items() if items}
    fitting_time = time.perf_counter() - started
    fits[COMMERCIAL_ACC] = commercial_acc({car: fits[car] for car in cars})
    presets = args.presets or (PRESETS_PATH if args.cars is None else None)  # a subset never overwrites the package's
    if presets is not None:
        write_presets(presets, fits, source=f"python -m train.calibrate_openacc, fit runs: {', '.join(run.name for run in fit_runs)}")

    measured = amplification(fit_runs + held_out_runs)
    args.out.mkdir(parents=True, exist_ok=True)
    write_csv(args.out / "calibration.csv", rows)
    plot_rmse(args.out / "calibration_rmse.png", rows)
    plot_example(args.out / "calibration_example.png", rows, test_segments)
    plot_stability(args.out / "calibration_stability.png", fits, measured)
    report = write_report(args.out / "calibration.md", rows, by_experiment, fits, measured, fit_runs, held_out_runs,
                          repeats)
    print(report)
    written = f"Presets written to {presets}." if presets else "No presets written (--cars without --presets)."
    print(f"Runtime: {fitting_time:.0f} s for the fits, {time.perf_counter() - started:.0f} s in all. {written}")


def write_csv(path: Path, rows: list[dict]) -> None:
    """One row per car model: fitted parameters, and every model's held-out errors."""
    with open(path, "w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(["car", *FollowerModel._fields, *(f"tau_{s}" for s in SETTINGS), "fit_spacing_rmse",
                         "held_out_segments", "held_out_seconds",
                         *(f"{model}: {measure}" for model in MODELS for measure in ("spacing_rmse", "speed_rmse", "dynamics_rmse"))])
        for row in rows:
            fit = row["fit"]
            writer.writerow([row["car"], *(f"{value:.4g}" for value in fit.model),
                             *(f"{fit.settings[s]:.4g}" if s in fit.settings else "" for s in SETTINGS),
                             f"{fit.spacing_rmse:.4g}", row["held_out"][0], f"{row['held_out'][1]:.0f}",
                             *(f"{row['errors'][model][measure]:.4g}" for model in MODELS
                               for measure in ("spacing_rmse", "speed_rmse", "dynamics_rmse"))])


def plot_rmse(path: Path, rows: list[dict]) -> None:
    """Held-out spacing RMSE, its dynamics part, and speed RMSE per car model, the three followers side by side."""
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.8), sharey=True)
    y = np.arange(len(rows))
    for ax, (measure, label) in zip(axes, (("spacing_rmse", "spacing RMSE [m]"), ("dynamics_rmse", "spacing RMSE, each segment's mean error removed [m]"), ("speed_rmse", "speed RMSE [m/s]"))):
        for k, model in enumerate(MODELS):
            ax.barh(y + (k - 1) * 0.27, [row["errors"][model][measure] for row in rows], height=0.27, label=model)
        ax.set_xlabel(label, fontsize=9)
        ax.grid(axis="x", alpha=0.3)
    axes[0].set_yticks(y, [row["car"] for row in rows], fontsize=8)
    axes[0].legend(fontsize=8)
    fig.suptitle("Held-out OpenACC runs: the three followers simulated behind the recorded predecessors", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_example(path: Path, rows: list[dict], test_segments: dict[str, list[tuple[Segment, str, str]]]) -> None:
    """For four car models, their longest held-out segment: recorded spacing and the calibrated follower's."""
    chosen = sorted(rows, key=lambda row: -row["held_out"][1])[:4]
    fig, axes = plt.subplots(len(chosen), 1, figsize=(10, 2.4 * len(chosen)), squeeze=False)
    for ax, row in zip(axes[:, 0], chosen):
        fit = row["fit"]
        segment, setting = max(((s, t) for s, t, _ in test_segments[row["car"]] if t in fit.settings),
                               key=lambda st: st[0].speed.size)
        t = np.arange(segment.speed.size) * BASE.dt
        simulated, _ = simulate_follower(segment, fit.model, fit.settings[setting], BASE)
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
    """Analytic peak gain of each calibrated car model beside its measured amplification, per setting."""
    fig, ax = plt.subplots(figsize=(6.5, 5))
    for k, setting in enumerate(SETTINGS):
        points = [(stability(fit.model, fit.settings[setting]).peak_gain, float(np.median(measured[car, setting])))
                  for car, fit in fits.items() if car != COMMERCIAL_ACC and setting in fit.settings and measured.get((car, setting))]
        if points:
            ax.scatter(*zip(*points), color=f"C{k}", label=f"setting {setting}")
    ax.axvline(1.0, color="0.5", lw=0.8)
    ax.axhline(1.0, color="0.5", lw=0.8)
    ax.set_xlabel("calibrated model: max |G(jω)|")
    ax.set_ylabel("measured: median std(v_follower) / std(v_predecessor)")
    ax.set_title("String stability: model against the real platoons", fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def write_report(
    path: Path, rows: list[dict], by_experiment: dict[str, dict[str, dict[str, float]]], fits: dict[str, FollowerFit], measured: dict[tuple[str, str], list[float]],
    fit_runs: list[OpenAccRun], held_out_runs: list[OpenAccRun], repeats: dict[str, str],
) -> str:
    """calibration.md: the method, parameters, held-out errors and string stability; returns its text."""
    lines = [
        "# Follower model calibrated to real commercial ACC cars (`python -m train.calibrate_openacc`)", "",
        f"Data: the OpenACC AstaZero runs (`timegap_env.default_openacc_dir()`): the {len(fit_runs) + len(held_out_runs)} ACC runs at setting S or "
        f"L, sorted by (setting, name), every other one fitted ({len(fit_runs)}), the rest held out ({len(held_out_runs)})"
        + "".join(f"; `{a}` repeats records of `{b}` and is left out" for a, b in repeats.items()) + ". "
        f"Segments: at least {MIN_SEGMENT:g} s with the car's speed, its predecessor's and the spacing recorded and the "
        f"spacing at most {FOLLOWING_MAX_SPACING:g} m (beyond it ACC cars cruise at their set speed and the gap opens: "
        "no car following to fit). Each follower is simulated behind the recorded predecessor from the segment's first "
        "record (the predecessor's position: the car's integrated speed plus the recorded spacing) and fitted by least "
        "squares on the spacing error (`timegap_env.sim.calibration`).",
        "Models: **calibrated** = GLVD + CTH in ACC with T, k_s, k_v, s0, the command's bounds and tau* per setting "
        f"fitted, K = 1 and k_a = {BASE.k_a} held (spacing and speed cannot tell K from the gains nor k_a from T); "
        "**default, tau* fitted** = the project's follower (T = 0.45 s, k_s = 0.2, k_v = 0.7, s0 = 5 m) with only tau* "
        "fitted; **constant time gap** = a follower that always keeps s = s0 + tau v (tau, s0 fitted).",
        "The fits also write the presets `timegap_env.acc_presets()` reads (`timegap_env/sim/acc_presets.json`).", "",
        "## Fitted parameters (fit runs)", "",
        "| car | T [s] | k_s [1/s²] | k_v [1/s] | s0 [m] | command bounds [m/s²] | τ* S [s] | τ* L [s] | fit spacing RMSE [m] (default follower's) | segments, duration |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for row in rows:
        fit = row["fit"]
        m = {name: _bounded(name, value, digits) for (name, value), digits in zip(fit.model._asdict().items(), (2, 3, 2, 1, 1, 1))}
        lines.append(f"| {row['car']} | {m['lag']} | {m['k_s']} | {m['k_v']} | {m['standstill_spacing']} | "
                     f"{m['accel_min']} / {m['accel_max']} | {_setting(fit, 'S')} | {_setting(fit, 'L')} | "
                     f"{fit.spacing_rmse:.2f} ({row['default'].spacing_rmse:.2f}) | {fit.n_segments}, {fit.duration:.0f} s |")
    median = fits[COMMERCIAL_ACC]
    m = median.model
    lines += [f"| **{COMMERCIAL_ACC}** (median) | {m.lag:.2f} | {m.k_s:.3f} | {m.k_v:.2f} | {m.standstill_spacing:.1f} | "
              f"{m.accel_min:.1f} / {m.accel_max:.1f} | {_setting(median, 'S')} | {_setting(median, 'L')} | | |", "",
              "`*`: the fit sits at the parameter's bound (`timegap_env.sim.calibration.BOUNDS`, `SETTING_BOUNDS`). Where the speed hardly "
              "varies within a car's segments, s0 and τ* trade off against each other (only s0 + τ* v is pinned down).", "",
              "## Held-out runs: spacing RMSE [m] / speed RMSE [m/s] (spacing RMSE with each segment's mean error removed)", "",
              "| car | held-out segments, duration | " + " | ".join(MODELS) + " |", "|---|---|---|---|---|"]
    for row in rows:
        cells = [f"{row['errors'][model]['spacing_rmse']:.2f} / {row['errors'][model]['speed_rmse']:.2f} "
                 f"({row['errors'][model]['dynamics_rmse']:.2f})" for model in MODELS]
        lines.append(f"| {row['car']} | {row['held_out'][0]}, {row['held_out'][1]:.0f} s | " + " | ".join(cells) + " |")
    wins = {model: sum(row["errors"][model]["spacing_rmse"] == min(row["errors"][m]["spacing_rmse"] for m in MODELS) for row in rows)
            for model in MODELS}
    lines += ["", "Lowest held-out spacing RMSE: " + ", ".join(f"{model} {count} of {len(rows)} cars" for model, count in wins.items()) + ".",
              "", "Pooled over the cars, by experiment (dynamic: speed oscillations around a cruise speed; handling: stops, "
              "starts, hard accelerations):", "", "| experiment | " + " | ".join(MODELS) + " |", "|---|---|---|---|"]
    for kind, errors in by_experiment.items():
        lines.append(f"| {kind} | " + " | ".join(f"{errors[model]['spacing_rmse']:.2f} / {errors[model]['speed_rmse']:.2f} "
                                                 f"({errors[model]['dynamics_rmse']:.2f})" for model in MODELS) + " |")
    lines += [
              "", "![held-out errors](calibration_rmse.png)", "![a held-out segment per car](calibration_example.png)", "",
              "## String stability: the calibrated models against the real platoons", "",
              "Analytic: max_ω |G(jω)| of the calibrated model at the setting's τ* (ACC, no V2V); above 1 (beyond a 1e-9 "
              "round-off allowance; |G(0)| = 1 exactly) is string unstable. "
              f"Measured: for every pair of consecutive cars of a run with {STABILITY_MIN_OVERLAP:g} s of common records, "
              "std(follower's speed) / std(predecessor's speed); > 1 means the car amplified the speed perturbations it "
              "received. Median and range over the pairs, and how many pairs amplified.", "",
              "| car | setting | peak gain, calibrated | peak gain, default τ* fitted | measured amplification: median [min, max] | pairs amplifying | agree |",
              "|---|---|---|---|---|---|---|"]
    agreements = []
    for row in rows:
        for setting in SETTINGS:
            values = measured.get((row["car"], setting))
            if setting not in row["fit"].settings or not values:
                continue
            analytic = stability(row["fit"].model, row["fit"].settings[setting])
            default = stability(row["default"].model, row["default"].settings[setting]).peak_gain
            median_amplification = float(np.median(values))
            agree = (not analytic.string_stable) == (median_amplification > 1.0)
            agreements.append(agree)
            lines.append(f"| {row['car']} | {setting} | {analytic.peak_gain:.3f} | {default:.3f} | {median_amplification:.3f} "
                         f"[{min(values):.2f}, {max(values):.2f}] | {sum(v > 1.0 for v in values)}/{len(values)} | "
                         f"{'yes' if agree else 'no'} |")
    lines += ["", f"The calibrated model's verdict (peak gain above or below 1) agrees with the measured median in "
              f"{sum(agreements)} of {len(agreements)} car-settings.", "", "![stability](calibration_stability.png)", ""]
    text = "\n".join(lines)
    path.write_text(text)
    return text


def _bounded(name: str, value: float, digits: int) -> str:
    """``value`` with ``digits`` decimals, starred when it sits at a bound of the fit."""
    low, high = BOUNDS[name]
    return f"{value:.{digits}f}" + ("*" if min(abs(value - low), abs(value - high)) < 1e-6 else "")


def _setting(fit: FollowerFit, setting: str) -> str:
    """The fitted tau* at ``setting`` [s], starred at a bound of the fit; a dash where the car has none."""
    if setting not in fit.settings:
        return "–"
    value = fit.settings[setting]
    return f"{value:.2f}" + ("*" if min(abs(value - bound) for bound in SETTING_BOUNDS) < 1e-6 else "")


if __name__ == "__main__":
    main()
