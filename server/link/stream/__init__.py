"""The setpoint streamer and what sends its frames on time: the sender process, its channel and
the sender thread."""
