"""The live 3D scene (viser), fed from vehicle snapshots and served through the app."""

from .hub import ClickPoint, SceneHub

__all__ = ["ClickPoint", "SceneHub"]
