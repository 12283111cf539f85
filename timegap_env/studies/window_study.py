"""The monitor window study's candidates and episodes, shared by ``train.choose_window`` (which chose the monitor's
default window) and ``train.field_validation`` (which re-examines the choice on recorded leaders)."""

from __future__ import annotations

from timegap_env.config import EnvConfig, SensorConfig

WINDOWS: list[float | None] = [0.5, 1.0, 2.0, 3.0, 5.0, 10.0, 20.0, None]  # [s]; None = all data since t = 0
FAMILIES = list(EnvConfig().scenario_weights)  # the env's default mix
SEEDS = range(15)
NOISY = SensorConfig(spacing_noise_std=0.5, speed_noise_std=0.5)

__all__ = ["FAMILIES", "NOISY", "SEEDS", "WINDOWS"]
