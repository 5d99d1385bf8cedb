"""`python -m sim`: the simulated PX4 vehicle as a process (see sim.process.cli)."""

from sim.process.cli import main

raise SystemExit(main())
