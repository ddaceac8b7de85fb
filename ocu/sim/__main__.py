"""Run the simulator: python -m ocu.sim."""

from ocu.sim.cli import main

raise SystemExit(main())
