"""The live 3D scene (viser), fed from vehicle snapshots and served through the app.

The package itself loads nothing: viser (half a second of imports) comes with ``hub`` and
``fleet_view``, which only a server that shows the scene imports; the scene's socket proxy
(``proxy``, also the Foxglove bridge's) does not need it."""
