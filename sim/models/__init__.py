"""The airframe models (multicopter, fixed wing, VTOL, rover) and running one in simulated
time."""
