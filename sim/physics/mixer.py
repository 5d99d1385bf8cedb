"""Multicopter mixer: seed 002's geometries through PX4's control allocation.

A geometry is a rotor table (position angle, spin direction, moment coefficient KM). From it
comes the effectiveness matrix B (roll, pitch, yaw torque and thrust per unit rotor output),
and the mix matrix is pinv(B), normalised as PX4's ControlAllocationPseudoInverse does so
that a full roll/pitch/yaw/thrust command maps to outputs of order one. Commands are
roll/pitch/yaw in [-1, 1] and thrust in [0, 1], scaled by the R: line's roll/pitch/yaw scales.

Desaturation keeps every output in [0, 1] and decides what to give up, in this order:
thrust first (shifted down, or up when an output would go below zero), then yaw, then roll
and pitch together (scaled, so the roll/pitch torque keeps its direction).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

# Reaction torque of a rotor relative to its thrust, as PX4's CA_ROTORn_KM (SIH: Q_MAX/T_MAX)
CA_ROTOR_KM = 0.05
CCW = 1
CW = -1
# mixer definition files store their scales multiplied by this (seed 002)
MIXER_SCALE = 10000


@dataclass(frozen=True)
class Rotor:
    """One rotor: where it sits (angle from the nose, clockwise seen from above) and its spin.

    A CCW rotor's reaction torque yaws the body clockwise (positive NED yaw), as PX4's
    positive CA_ROTORn_KM.
    """

    angle_deg: float
    spin: int
    km: float = CA_ROTOR_KM

    def position_frd(self, arm_length_m: float) -> tuple[float, float]:
        a = math.radians(self.angle_deg)
        return (arm_length_m * math.cos(a), arm_length_m * math.sin(a))


# Rotor order and spins as PX4's legacy multirotor mixer geometries (seed 002's R: lines).
GEOMETRIES: dict[str, tuple[Rotor, ...]] = {
    "4x": (Rotor(45, CCW), Rotor(225, CCW), Rotor(315, CW), Rotor(135, CW)),
    "4+": (Rotor(90, CCW), Rotor(270, CCW), Rotor(0, CW), Rotor(180, CW)),
    "6x": (
        Rotor(90, CW), Rotor(270, CCW), Rotor(330, CW),
        Rotor(150, CCW), Rotor(30, CCW), Rotor(210, CW),
    ),
    "6+": (
        Rotor(0, CW), Rotor(180, CCW), Rotor(240, CW),
        Rotor(60, CCW), Rotor(300, CCW), Rotor(120, CW),
    ),
    "8x": (
        Rotor(22.5, CW), Rotor(202.5, CW), Rotor(67.5, CCW), Rotor(157.5, CCW),
        Rotor(337.5, CCW), Rotor(247.5, CCW), Rotor(292.5, CW), Rotor(112.5, CW),
    ),
    "8+": (
        Rotor(0, CW), Rotor(180, CW), Rotor(45, CCW), Rotor(135, CCW),
        Rotor(315, CCW), Rotor(225, CCW), Rotor(270, CW), Rotor(90, CW),
    ),
}


def effectiveness_matrix(rotors: tuple[Rotor, ...]) -> np.ndarray:
    """B: rows roll, pitch, yaw torque and thrust per unit output, for a unit arm and thrust.

    Thrust along body -z at (x, y) gives roll torque -y and pitch torque +x.
    """
    b = np.zeros((4, len(rotors)))
    for i, rotor in enumerate(rotors):
        x, y = rotor.position_frd(1.0)
        b[0, i] = -y
        b[1, i] = x
        b[2, i] = rotor.spin * rotor.km
        b[3, i] = 1.0
    b[np.abs(b) < 1e-9] = 0.0
    return b


def normalized_mix_matrix(b: np.ndarray) -> np.ndarray:
    """pinv(B) with PX4's column normalisation (one scale for roll and pitch, yaw by its
    largest entry, thrust by the mean so that full thrust is every output at one)."""
    mix = np.linalg.pinv(b)
    roll_pitch_scale = 0.0
    for axis in (0, 1):
        column = mix[:, axis]
        nonzero = int(np.count_nonzero(np.abs(column) > 1e-3))
        if nonzero:
            roll_pitch_scale = max(
                roll_pitch_scale, math.sqrt(float(column @ column) / (nonzero / 2.0))
            )
    mix[:, 0] /= roll_pitch_scale
    mix[:, 1] /= roll_pitch_scale
    mix[:, 2] /= float(np.max(mix[:, 2]))
    mix[:, 3] /= float(np.mean(mix[:, 3]))
    mix[np.abs(mix) < 1e-6] = 0.0
    return mix


class Mixer:
    """The `R: <geometry> <roll scale> <pitch scale> <yaw scale>` mixer of seed 002."""

    def __init__(
        self,
        geometry: str,
        roll_scale: float = 1.0,
        pitch_scale: float = 1.0,
        yaw_scale: float = 1.0,
    ) -> None:
        if geometry not in GEOMETRIES:
            raise ValueError(f"unknown geometry {geometry!r}; known: {', '.join(GEOMETRIES)}")
        self.geometry = geometry
        self.rotors = GEOMETRIES[geometry]
        self.effectiveness = effectiveness_matrix(self.rotors)
        mix = normalized_mix_matrix(self.effectiveness)
        self._roll = [float(v) * roll_scale for v in mix[:, 0]]
        self._pitch = [float(v) * pitch_scale for v in mix[:, 1]]
        self._yaw = [float(v) * yaw_scale for v in mix[:, 2]]
        self._thrust = [float(v) for v in mix[:, 3]]
        self.rotor_count = len(self.rotors)
        self.saturated = False

    @classmethod
    def from_definition(cls, line: str) -> Mixer:
        """A mixer from seed 002's text form, `R: <geometry> <roll> <pitch> <yaw> <deadband>`,
        scales stored ×10000 (`R: 4x 10000 10000 10000 0`). The deadband is accepted and
        ignored, as by PX4's later multirotor mixers."""
        fields = line.split()
        if len(fields) < 5 or fields[0] != "R:":
            raise ValueError(f"not a multirotor mixer definition: {line!r}")
        roll, pitch, yaw = (int(v) / MIXER_SCALE for v in fields[2:5])
        return cls(fields[1], roll, pitch, yaw)

    def mix(self, roll: float, pitch: float, yaw: float, thrust: float) -> list[float]:
        """Rotor outputs in [0, 1] for normalised roll/pitch/yaw in [-1, 1], thrust in [0, 1]."""
        roll = _clamp_finite(roll, -1.0, 1.0)
        pitch = _clamp_finite(pitch, -1.0, 1.0)
        yaw = _clamp_finite(yaw, -1.0, 1.0)
        thrust = _clamp_finite(thrust, 0.0, 1.0)
        rp = [r * roll + p * pitch for r, p in zip(self._roll, self._pitch, strict=True)]
        yw = [y * yaw for y in self._yaw]
        # The symmetric geometries have a uniform thrust column, so thrust shifts every
        # output equally and only the spread of the attitude terms decides what fits.
        rp_spread = max(rp) - min(rp)
        self.saturated = False
        if rp_spread > 1.0:
            self.saturated = True
            k = 1.0 / rp_spread
            rp = [v * k for v in rp]
            attitude = rp
        else:
            attitude = [a + b for a, b in zip(rp, yw, strict=True)]
            if max(attitude) - min(attitude) > 1.0:
                self.saturated = True
                k = _largest_yaw_fraction_that_fits(rp, yw)
                attitude = [a + k * b for a, b in zip(rp, yw, strict=True)]
        low, high = min(attitude), max(attitude)
        shifted = min(max(thrust, -low), 1.0 - high)
        if shifted != thrust:
            self.saturated = True
        return [
            min(1.0, max(0.0, a + shifted * t))
            for a, t in zip(attitude, self._thrust, strict=True)
        ]

    def torque_and_thrust(self, outputs: list[float]) -> tuple[float, float, float, float]:
        """What the outputs achieve in the effectiveness frame (roll, pitch, yaw, thrust)."""
        b = self.effectiveness
        u = np.asarray(outputs, dtype=float)
        achieved = b @ u
        return (float(achieved[0]), float(achieved[1]), float(achieved[2]), float(achieved[3]))


def _largest_yaw_fraction_that_fits(rp: list[float], yw: list[float]) -> float:
    """Largest k in [0, 1] with spread(rp + k·yw) ≤ 1 (given spread(rp) ≤ 1).

    The spread is convex in k, so bisection finds the boundary.
    """
    lo, hi = 0.0, 1.0
    for _ in range(20):
        mid = 0.5 * (lo + hi)
        values = [a + mid * b for a, b in zip(rp, yw, strict=True)]
        if max(values) - min(values) <= 1.0:
            lo = mid
        else:
            hi = mid
    return lo


def _clamp_finite(value: float, low: float, high: float) -> float:
    if value != value:  # NaN: no command on that axis
        return 0.0
    return min(high, max(low, value))
