"""Loop functions that raise at a given tick: a failing experiment's code."""


class RaisingLoopFunctions:
    """No base class: every hook is optional."""

    def __init__(self, raise_at_tick: int = 3):
        self.raise_at = raise_at_tick

    def post_step(self, sim) -> None:
        if sim.tick == self.raise_at:
            raise RuntimeError(f"the experiment's own bug at tick {sim.tick}")

    def metrics(self, sim) -> dict:
        return {"mean_x": float(sim.positions[:, 0].mean())}
