"""`python -m sim`: the simulated PX4 vehicle as a process (see sim.cli)."""

from sim.cli import main

raise SystemExit(main())
