"""Which mode a vehicle on the ground is armed in.

PX4 (v1.16) refuses to arm in some modes for no fault of the vehicle: the modes of
mode_requirements.cpp's ``mode_req_prevent_arming`` ("Mode not suitable for arming"), and
OFFBOARD while no setpoint stream runs ("No offboard signal"). A vehicle lands in them by
itself: after an RTL or a Land ends disarmed, PX4's UserModeIntention::onDisarm goes back
to the last mode chosen that does not prevent arming, which is OFFBOARD for a vehicle
flown offboard, and the stream that was flying it has stopped. A ground station that
arms from there must choose a mode first, as QGroundControl's takeoff does (it switches
to Takeoff, then arms). Every other refusal (failing checks, battery, geofence) is the
vehicle's own answer and is passed on unchanged.
"""

from __future__ import annotations

from server.link.codec.arming_checks import MODES_PREVENTING_ARMING

# mode_requirements.cpp: mode_req_prevent_arming (codec/arming_checks.py). TERMINATION
# prevents arming too, but PX4 never leaves it (UserModeIntention::change), so no mode
# switch could help.
__all__ = ["ARMING_MODE", "MODES_PREVENTING_ARMING", "mode_to_arm_in"]

# the mode a PX4 vehicle starts in, and arms in with a global position and nothing else
ARMING_MODE = "HOLD"


def mode_to_arm_in(mode: str | None, offboard_streaming: bool) -> str | None:
    """The mode to switch to before arming a vehicle reporting ``mode``; None to arm in
    the mode it is in."""
    if mode in MODES_PREVENTING_ARMING:
        return ARMING_MODE
    if mode == "OFFBOARD" and not offboard_streaming:
        return ARMING_MODE
    return None
