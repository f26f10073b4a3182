"""A controller plugin whose module cannot be imported (a dependency is missing)."""
import composed_sim_missing_dependency  # noqa: F401 - the missing import is the test's point
