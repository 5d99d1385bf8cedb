"""How a vehicle's state is coloured in the scene: one place for the policy."""

from __future__ import annotations

from typing import Literal

Rgb = tuple[int, int, int]
StateCategory = Literal["disarmed", "armed", "offboard", "failsafe"]

STATE_COLOURS: dict[StateCategory, Rgb] = {
    "disarmed": (140, 146, 156),
    "armed": (46, 204, 113),
    "offboard": (52, 152, 219),
    "failsafe": (231, 76, 60),
}

# MAV_STATE values PX4 reports while a failsafe is active.
_FAILSAFE_SYSTEM_STATUS = frozenset({"CRITICAL", "EMERGENCY", "FLIGHT_TERMINATION"})


def state_category(
    *, armed: bool, mode: str, user_mode: str | None, system_status: str
) -> StateCategory:
    """Failsafe wins; then offboard; then armed / disarmed.

    A failsafe shows either as MAV_STATE_CRITICAL or as the vehicle flying another mode than
    the one the user chose (PX4 keeps the user-intended mode, e.g. OFFBOARD, while the
    COM_OBL_RC_ACT fallback flies).
    """
    if armed and (
        system_status.upper().removeprefix("MAV_STATE_") in _FAILSAFE_SYSTEM_STATUS
        or (user_mode is not None and user_mode != mode)
    ):
        return "failsafe"
    if not armed:
        return "disarmed"
    if mode == "OFFBOARD":
        return "offboard"
    return "armed"


def state_colour(
    *, armed: bool, mode: str, user_mode: str | None, system_status: str
) -> Rgb:
    category = state_category(
        armed=armed, mode=mode, user_mode=user_mode, system_status=system_status
    )
    return STATE_COLOURS[category]


def blend(colour: Rgb, background: Rgb, weight: float) -> Rgb:
    """Linear mix: weight 1 gives `colour`, 0 gives `background` (fading trails)."""
    w = min(1.0, max(0.0, weight))
    r, g, b = (round(c * w + bg * (1.0 - w)) for c, bg in zip(colour, background, strict=True))
    return (r, g, b)


def rotor_colour(output: float) -> Rgb:
    """Rotor disc colour for a motor output 0..1: dark idle, through amber, to white at full."""
    x = min(1.0, max(0.0, output))
    if x < 0.5:
        return blend((255, 170, 0), (60, 60, 70), x * 2.0)
    return blend((255, 255, 255), (255, 170, 0), (x - 0.5) * 2.0)
