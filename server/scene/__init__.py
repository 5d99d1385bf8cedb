"""The live 3D scene (viser), fed from vehicle snapshots and served through the app.

Its two classes load viser (half a second of imports) when first asked for: the scene's
socket proxy (``server.scene.proxy``, also the Foxglove bridge's) does not need it."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from .fleet_view import FleetScene
    from .hub import SceneHub

__all__ = ["FleetScene", "SceneHub"]


def __getattr__(name: str) -> Any:
    if name == "FleetScene":
        from .fleet_view import FleetScene

        return FleetScene
    if name == "SceneHub":
        from .hub import SceneHub

        return SceneHub
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
