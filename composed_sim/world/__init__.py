"""World description: the schema (``World``) and the YAML loader/writer."""
from composed_sim.world.loader import (WorldFileError, dump_world, load_world, split_count,
                                       with_overrides, world_from_dict)
from composed_sim.world.schema import World

__all__ = ["World", "WorldFileError", "dump_world", "load_world", "split_count",
           "with_overrides", "world_from_dict"]
