"""Analytic string stability of the CTH controller on GLVD followers.

The transfer function from the predecessor's acceleration to the follower's is

    G(s) = K (k_f s^2 e^{-theta s} H(s) + k_v s + k_s)
           / (T s^3 + (1 - K k_a) s^2 + K (k_v + k_s tau*) s + K k_s),

H(s) = (1 - p) / (1 - p e^{-s dt}) the mean effect of losing each V2V message with chance p and
holding the last one received (a geometric extra delay of whole ticks; H = 1 without loss).
The model is continuous in time: it ignores the simulator's hold of the command over each tick.

A platoon is string stable iff max_w |G(jw)| <= 1 (disturbances do not grow
down the platoon), and locally stable iff the denominator is Hurwitz:
1 - K k_a > 0, K k_s > 0, K (k_v + k_s tau*) > 0 and
(1 - K k_a) K (k_v + k_s tau*) > T K k_s.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from timegap_env.config import PlatoonConfig

# |G(0)| = 1 exactly, so "<= 1" is judged with this round-off allowance [-].
PEAK_GAIN_TOLERANCE = 1e-9
FREQUENCY_GRID = np.concatenate([[0.0], np.logspace(-4, 3, 8000)])  # [rad/s]


@dataclasses.dataclass(frozen=True)
class StabilityReport:
    """Result of :func:`string_stability`."""

    peak_gain: float  # max_w |G(jw)| [-]
    peak_frequency: float  # w at the peak [rad/s]
    string_stable: bool  # peak_gain <= 1
    locally_stable: bool  # closed loop of one follower is Hurwitz


class SettingSweep:
    """One follower's :func:`string_stability` at any setting tau*: the parts of G(jw) that do not depend on
    tau* (the numerator, the denominator's s^3 and s^2 terms) are computed once, so that a search over
    settings (:func:`~timegap_env.sim.degradation.smallest_stable_setting`) evaluates only the rest. The
    arguments are :func:`transfer_gain`'s but ``setting``, which :meth:`gains` and :meth:`report` take."""

    def __init__(self, *, k_s: float, k_v: float, k_a: float, k_f: float, lag: float, gain: float, delay: float,
                 packet_loss: float = 0.0, dt: float = PlatoonConfig.dt, frequency: np.ndarray = FREQUENCY_GRID) -> None:
        for name, value in (("lag", lag), ("gain", gain)):
            if not np.isfinite(value) or value <= 0:
                raise ValueError(f"{name} = {value!r}: must be finite and > 0")
        if not np.isfinite(delay) or delay < 0:
            raise ValueError(f"delay = {delay!r}: must be finite and >= 0")
        if not 0 <= packet_loss < 1:
            raise ValueError(f"packet_loss = {packet_loss!r}: must be in [0, 1)")
        self.k_s, self.k_v, self.k_a, self.lag, self.gain = k_s, k_v, k_a, lag, gain
        self.frequency = np.asarray(frequency, dtype=float)  # w [rad/s]
        s = self._s = 1j * self.frequency
        held = (1.0 - packet_loss) / (1.0 - packet_loss * np.exp(-dt * s))
        self._numerator = gain * (k_f * s**2 * np.exp(-delay * s) * held + k_v * s + k_s)
        self._leading = lag * s**3 + (1 - gain * k_a) * s**2  # the denominator's first terms, added first

    def gains(self, setting: float) -> np.ndarray:
        """|G(jw)| at each frequency for the setting tau* ``setting`` [s]."""
        denominator = self._leading + self.gain * (self.k_v + self.k_s * setting) * self._s + self.gain * self.k_s
        return np.abs(self._numerator / denominator)

    def report(self, setting: float) -> StabilityReport:
        """:func:`string_stability`'s verdicts at the setting tau* ``setting`` [s]."""
        if not np.isfinite(setting) or setting <= 0:
            raise ValueError(f"setting = {setting!r}: must be finite and > 0")
        gains = self.gains(setting)
        peak = int(np.argmax(gains))
        gain, lag, k_s = self.gain, self.lag, self.k_s
        damping = 1 - gain * self.k_a
        velocity_term = gain * (self.k_v + k_s * setting)
        locally_stable = bool(
            damping > 0 and gain * k_s > 0 and velocity_term > 0 and damping * velocity_term > lag * gain * k_s
        )
        return StabilityReport(
            peak_gain=float(gains[peak]),
            peak_frequency=float(self.frequency[peak]),
            string_stable=bool(gains[peak] <= 1 + PEAK_GAIN_TOLERANCE),
            locally_stable=locally_stable,
        )


def transfer_gain(
    frequency: np.ndarray,
    *,
    k_s: float,
    k_v: float,
    k_a: float,
    k_f: float,
    setting: float,
    lag: float,
    gain: float,
    delay: float,
    packet_loss: float = 0.0,
    dt: float = PlatoonConfig.dt,
) -> np.ndarray:
    """|G(jw)| at each ``frequency`` w [rad/s]; ``setting`` tau* [s], ``lag`` T [s], ``gain`` K, ``delay`` theta [s],
    ``packet_loss`` p [-] of the V2V messages sent every ``dt`` [s]."""
    return SettingSweep(k_s=k_s, k_v=k_v, k_a=k_a, k_f=k_f, lag=lag, gain=gain, delay=delay, packet_loss=packet_loss,
                        dt=dt, frequency=frequency).gains(setting)


def string_stability(
    *,
    k_s: float,
    k_v: float,
    k_a: float,
    k_f: float,
    setting: float,
    lag: float,
    gain: float,
    delay: float,
    packet_loss: float = 0.0,
    dt: float = PlatoonConfig.dt,
) -> StabilityReport:
    """Peak gain of G and the string and local stability verdicts for one follower.

    ``k_f = 0`` is ACC (no V2V); the other arguments are as in :func:`transfer_gain`.
    """
    return SettingSweep(k_s=k_s, k_v=k_v, k_a=k_a, k_f=k_f, lag=lag, gain=gain, delay=delay, packet_loss=packet_loss,
                        dt=dt).report(setting)


def platoon_string_stability(config: PlatoonConfig, *, setting: float | None = None, v2v: bool | None = None) -> list[StabilityReport]:
    """One :class:`StabilityReport` per follower of ``config`` (its own T and K), at ``setting`` tau* [s]
    (default ``config.initial_setting``) and V2V state."""
    setting = config.initial_setting if setting is None else setting
    v2v = config.v2v if v2v is None else v2v
    return [
        string_stability(
            k_s=config.k_s,
            k_v=config.k_v,
            k_a=config.k_a,
            k_f=config.k_f if v2v else 0.0,
            setting=setting,
            lag=float(lag),
            gain=float(gain),
            delay=config.v2v_delay,
        )
        for lag, gain in zip(config.per_follower("actuation_lag"), config.per_follower("actuation_gain"))
    ]
