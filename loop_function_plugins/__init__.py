"""Loop functions shipped with composed_sim, registered in the entry-point group
``composed_sim.loop_functions`` (composed_sim/loop_functions.py describes the hooks)."""
