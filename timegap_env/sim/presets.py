"""Followers calibrated to real commercial ACC cars (OpenACC), ready to simulate.

``acc_presets()`` maps each car model (e.g. ``"TESLA_MODEL3"``) and ``COMMERCIAL_ACC``, the median
car, to its :class:`~timegap_env.sim.calibration.FollowerFit`; ``acc_platoon(car, distance_setting)`` is a
:class:`~timegap_env.config.PlatoonConfig` of that car in ACC at distance setting ``"S"`` or ``"L"``::

    timegap_env.simulate("paper", timegap_env.acc_platoon("TESLA_MODEL3", "L"))

The numbers live in ``acc_presets.json`` beside this module, written by
``python -m train.calibrate_openacc`` (see ``results/field/calibration.md`` for how well each fits).
The env takes a platoon's ``initial_setting`` from its ladder ``setting_levels``: pass
``initial_setting=`` (a level) to ``acc_platoon`` for use in the env.
"""

from __future__ import annotations

import functools
import json
from pathlib import Path

from timegap_env.config import PlatoonConfig
from timegap_env.sim.calibration import FollowerFit, FollowerModel

PRESETS_PATH = Path(__file__).with_name("acc_presets.json")
COMMERCIAL_ACC = "COMMERCIAL_ACC"  # the median of the calibrated car models


@functools.lru_cache(maxsize=4)
def acc_presets(path: Path = PRESETS_PATH) -> dict[str, FollowerFit]:
    """The calibrated followers by car model, and ``COMMERCIAL_ACC``, read from ``path``."""
    document = json.loads(Path(path).read_text())
    return {
        car: FollowerFit(
            model=FollowerModel(**entry["model"]),
            settings=entry["settings"],
            spacing_rmse=entry["spacing_rmse"],
            n_segments=entry["n_segments"],
            duration=entry["duration"],
        )
        for car, entry in document["cars"].items()
    }


def acc_platoon(car: str = COMMERCIAL_ACC, distance_setting: str = "S", base: PlatoonConfig = PlatoonConfig(),
                **overrides: object) -> PlatoonConfig:
    """``base`` with every follower the calibrated ``car`` in ACC at ``distance_setting``; ``overrides`` on top."""
    presets = acc_presets()
    if car not in presets:
        raise ValueError(f"car = {car!r}: no calibrated preset; known: {sorted(presets)}")
    fit = presets[car]
    if distance_setting not in fit.settings:
        raise ValueError(f"distance_setting = {distance_setting!r}: {car} was calibrated at {sorted(fit.settings)}")
    return fit.platoon_config(distance_setting, base, **overrides)


def write_presets(path: Path, fits: dict[str, FollowerFit], source: str) -> None:
    """Write ``fits`` as the presets file at ``path`` (sorted keys, floats in full), with where they came from."""
    cars = {
        car: {
            "model": fit.model._asdict(),
            "settings": dict(sorted(fit.settings.items())),
            "spacing_rmse": fit.spacing_rmse,
            "n_segments": fit.n_segments,
            "duration": fit.duration,
        }
        for car, fit in sorted(fits.items())
    }
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    Path(path).write_text(json.dumps({"source": source, "cars": cars}, indent=1) + "\n")
    acc_presets.cache_clear()
