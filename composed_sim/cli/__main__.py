"""``python -m composed_sim.cli``: the ``composed-sim`` command."""
import sys

from composed_sim.cli import main

sys.exit(main())
