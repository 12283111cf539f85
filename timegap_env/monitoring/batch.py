"""Argument checks shared by the monitor and the charts, whose arrays are (n_envs, n_vehicles).

Each raises ``ValueError`` naming the argument and the value at fault.
"""

from __future__ import annotations

import numba
import numpy as np
from numpy.typing import ArrayLike

from timegap_env.compiled import follow_sources


def batch_shape(n_envs: int, n_vehicles: int) -> tuple[int, int]:
    """(n_envs, n_vehicles), both checked to be integers >= 1."""
    for name, value in (("n_envs", n_envs), ("n_vehicles", n_vehicles)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
            raise ValueError(f"{name} = {value!r}: must be an integer >= 1")
    return int(n_envs), int(n_vehicles)


def batch_array(name: str, value: ArrayLike, shape: tuple[int, int]) -> np.ndarray:
    """``value`` as a float array of exactly ``shape`` (n_envs, n_vehicles); ValueError naming ``name``."""
    try:
        array = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{name} = {value!r}: must be numbers") from None
    if array.shape != shape:
        raise ValueError(f"{name} has shape {array.shape}: expected {shape} (n_envs, n_vehicles)")
    return array


def setting_array(setting: ArrayLike, shape: tuple[int, int]) -> np.ndarray:
    """A time gap ``setting`` [s] broadcast to ``shape``, every value finite and > 0."""
    array = np.asarray(setting, dtype=float)
    if array.shape != shape:
        try:
            array = np.broadcast_to(array, shape)
        except ValueError:
            raise ValueError(f"setting has shape {array.shape}: not broadcastable to {shape}") from None
    valid = (array > 0) & (array < np.inf)  # NaN fails both
    if not valid.all():  # called every tick: find the culprit only when there is one
        bad = np.argwhere(~valid)
        index = tuple(int(i) for i in bad[0])
        raise ValueError(f"setting{list(index)} = {float(array[index])}: must be finite and > 0 [s]")
    return array


def vehicle_mask(mask: ArrayLike | None, shape: tuple[int, int]) -> np.ndarray:
    """Boolean mask of vehicles broadcast to ``shape`` (n_envs, n_vehicles); None selects all."""
    if mask is None:
        return np.ones(shape, dtype=bool)
    array = np.asarray(mask)
    if array.dtype != bool:
        raise ValueError(f"mask has dtype {array.dtype}: must be bool")
    if array.shape == shape:
        return array
    try:
        return np.broadcast_to(array, shape)
    except ValueError:
        raise ValueError(f"mask has shape {array.shape}: not broadcastable to {shape} (n_envs, n_vehicles)") from None


def env_mask(mask: ArrayLike | None, n_envs: int) -> np.ndarray:
    """Boolean mask of envs, shape (n_envs,); None selects all."""
    if mask is None:
        return np.ones(n_envs, dtype=bool)
    array = np.asarray(mask)
    if array.dtype != bool or array.shape != (n_envs,):
        raise ValueError(f"mask has dtype {array.dtype} and shape {array.shape}: must be bool of shape ({n_envs},)")
    return array


def check_finite(**named: np.ndarray) -> None:
    """ValueError naming the first non-finite value of the arrays given by name; called every tick, so a
    compiled scan looks first and the culprit is searched only when there is one."""
    for name, values in named.items():
        if not _all_finite(values.reshape(-1)):
            index = tuple(int(i) for i in np.argwhere(~np.isfinite(values))[0])
            raise ValueError(f"{name}{list(index)} = {values[index]}: must be finite")


@numba.njit(cache=True)
def _all_finite(values):  # noqa: ANN001, ANN202
    """Whether every value of the 1-D array ``values`` is finite."""
    for value in values:
        if not np.isfinite(value):
            return False
    return True


# Its kernel: numba's cache by content
follow_sources(__name__)
