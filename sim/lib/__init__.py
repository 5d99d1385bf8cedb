"""What every layer uses: uORB-like topics, parameters, flight mode names, quaternions, numeric
and geodetic helpers, PX4's events and extra MAVLink messages."""
