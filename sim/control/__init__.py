"""The controllers, after PX4's mc_pos/att/rate_control and fw_control."""
