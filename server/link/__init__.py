"""MAVLink link layer: connections, vehicles, commands, setpoints and telemetry state.

Nothing of HTTP, pydantic or viser is imported here.
"""

from .link import Link
from .link_stats import LinkStats

__all__ = ["Link", "LinkStats"]
