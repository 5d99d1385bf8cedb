"""The simulator as a process: the command line, the vehicles' runner, the stepping loop and its
clock, child processes."""
