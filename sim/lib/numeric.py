"""Scalar helpers of the physics and controllers' hot path (plain floats, no numpy)."""

from __future__ import annotations

import math


def is_finite(x: float) -> bool:
    """False for NaN ("not controlled" in a setpoint) and for ±inf."""
    return x == x and x not in (math.inf, -math.inf)


def clamp(x: float, low: float, high: float) -> float:
    return low if x < low else high if x > high else x


def finite_or(x: float, default: float) -> float:
    return x if is_finite(x) else default
