"""The rigid body, aerodynamics, the mixer and the battery."""
