"""A drone show as a user writes one for Crazyswarm2: a run-wide node that calls the swarm's and the
drones' services on its clock (no composed_sim import)."""
