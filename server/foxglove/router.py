"""Every MAVLink frame of one link onto its channels (a Link frame tap, or a .tlog's
records): its own message channel, and the derived pose, position and texts. A message is
encoded only for a channel that has a reader; otherwise a frame costs a lookup or two."""

from __future__ import annotations

import logging

from pymavlink.dialects.v20 import development as mavlink

from server.foxglove.channels import LinkChannels
from server.foxglove.derived import Derived
from server.foxglove.mavlink_json import message_json

log = logging.getLogger(__name__)

_DERIVED_KINDS = frozenset({"GLOBAL_POSITION_INT", "LOCAL_POSITION_NED", "ATTITUDE", "STATUSTEXT"})


class FrameRouter:
    def __init__(self, channels: LinkChannels) -> None:
        self.channels = channels
        self._derived: dict[int, Derived] = {}
        self._failed = False

    def derived(self, sysid: int) -> Derived:
        derived = self._derived.get(sysid)
        if derived is None:
            derived = self._derived[sysid] = Derived(self.channels.vehicle(sysid))
        return derived

    def frame(self, msg: mavlink.MAVLink_message, sent: bool, unix_time_s: float) -> None:
        """A frame the link received (sent False) or sent, at that Unix time."""
        try:
            self._route(msg, sent, int(unix_time_s * 1e9))
        except Exception:
            # the link's receive path must go on whatever a view of it does
            if not self._failed:
                self._failed = True
                log.exception("foxglove: cannot publish %s", msg.get_type())

    def _route(self, msg: mavlink.MAVLink_message, sent: bool, time_ns: int) -> None:
        sysid = (getattr(msg, "target_system", 0) or 0) if sent else msg.get_srcSystem()
        channel = self.channels.mavlink(sysid, sent, msg)
        if channel.has_sinks():
            channel.base.log(message_json(msg), time_ns)
        kind = msg.get_type()
        if not sent and kind in _DERIVED_KINDS:
            self.derived(sysid).handlers[kind](msg, time_ns)
