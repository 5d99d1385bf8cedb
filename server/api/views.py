"""Vehicle state as the API shows it: the link's snapshot with API names (`id`, `type`,
`global`), the lease, and non-finite numbers as null (JSON has no NaN)."""

from __future__ import annotations

import math
from dataclasses import asdict
from typing import Any

from server.api.lease import LeaseManager
from server.link import StreamStats, VehicleState


def finite(value: Any) -> Any:
    """The value with every NaN/inf float, however deeply nested, replaced by None."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {key: finite(item) for key, item in value.items()}
    if isinstance(value, list | tuple):
        return [finite(item) for item in value]
    return value


def state_dict(state: VehicleState, leases: LeaseManager) -> dict[str, Any]:
    raw = asdict(state)
    raw["id"] = state.sysid
    raw["type"] = raw.pop("mav_type")
    raw["global"] = raw.pop("global_position")
    holder, expires_in_s = leases.status(state.sysid)
    raw["lease"] = {"holder": holder, "expires_in_s": expires_in_s}
    result: dict[str, Any] = finite(raw)
    return result


def summary_dict(state: VehicleState) -> dict[str, Any]:
    result: dict[str, Any] = finite(
        {
            "id": state.sysid,
            "sysid": state.sysid,
            "type": state.mav_type,
            "autopilot": state.autopilot,
            "connected": state.connected,
            "mode": state.mode,
            "armed": state.armed,
            "link": asdict(state.link),
        }
    )
    return result


def stream_dict(stats: StreamStats) -> dict[str, Any]:
    result: dict[str, Any] = finite(asdict(stats))
    return result
