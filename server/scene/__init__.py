"""The live 3D scene (viser), fed from vehicle snapshots and served through the app."""

from .fleet_view import FleetScene
from .hub import SceneHub

__all__ = ["FleetScene", "SceneHub"]
