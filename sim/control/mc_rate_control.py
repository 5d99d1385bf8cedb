"""Multicopter body-rate control after PX4's mc_rate_control (RateControl).

PID on body rates with integrator limits, frozen while landed or while the mixer
saturates; the output is normalised torque for the mixer.
"""

from __future__ import annotations

import functools
import math

from sim.lib.numeric import clamp
from sim.lib.params import ParamReader, param_or
from sim.lib.quat import Vec3


class RateControl:
    """PX4 RateControl: PID on body rates with integrator limits, frozen while landed."""

    def __init__(self) -> None:
        self.rate_int = [0.0, 0.0, 0.0]
        self._prev_rates: Vec3 | None = None
        self.read_params_from(None)

    def read_params_from(self, params: ParamReader | None) -> None:
        get = functools.partial(param_or, params)
        k = (get("MC_ROLLRATE_K", 1.0), get("MC_PITCHRATE_K", 1.0), get("MC_YAWRATE_K", 1.0))
        self.gain_p = (
            k[0] * get("MC_ROLLRATE_P", 0.15),
            k[1] * get("MC_PITCHRATE_P", 0.15),
            k[2] * get("MC_YAWRATE_P", 0.2),
        )
        self.gain_i = (
            k[0] * get("MC_ROLLRATE_I", 0.2),
            k[1] * get("MC_PITCHRATE_I", 0.2),
            k[2] * get("MC_YAWRATE_I", 0.1),
        )
        self.gain_d = (
            k[0] * get("MC_ROLLRATE_D", 0.003),
            k[1] * get("MC_PITCHRATE_D", 0.003),
            k[2] * get("MC_YAWRATE_D", 0.0),
        )
        self.int_lim = (
            get("MC_RR_INT_LIM", 0.3),
            get("MC_PR_INT_LIM", 0.3),
            get("MC_YR_INT_LIM", 0.3),
        )

    def reset(self) -> None:
        self.rate_int = [0.0, 0.0, 0.0]
        self._prev_rates = None

    def update(
        self, dt_s: float, rates: list[float], rates_sp: Vec3, landed: bool, saturated: bool
    ) -> Vec3:
        prev = self._prev_rates
        current = (rates[0], rates[1], rates[2])
        self._prev_rates = current
        out = [0.0, 0.0, 0.0]
        for i in range(3):
            err = rates_sp[i] - current[i]
            accel = 0.0 if prev is None else (current[i] - prev[i]) / dt_s
            out[i] = self.gain_p[i] * err + self.rate_int[i] - self.gain_d[i] * accel
            if not landed and not saturated:
                # PX4 shrinks the integration for large errors to avoid windup on flips
                i_factor = max(0.0, 1.0 - (err / math.radians(400.0)) ** 2)
                lim = self.int_lim[i]
                self.rate_int[i] = clamp(
                    self.rate_int[i] + i_factor * self.gain_i[i] * err * dt_s, -lim, lim
                )
        return (out[0], out[1], out[2])
