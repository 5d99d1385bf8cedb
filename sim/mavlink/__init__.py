"""MAVLink in and out, after PX4's mavlink module: UDP endpoints, the receiver, commands,
offboard setpoints, parameters, FTP, events services and the telemetry streams, and the view of
a vehicle they share."""
