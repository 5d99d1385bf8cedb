"""The vehicle's plugins, one per MAVLink concern (action, offboard, telemetry, parameters,
events, manual control): each drives the core, none owns the link."""
