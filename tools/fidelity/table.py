#!/usr/bin/env python3
"""Print docs/fidelity.md's tables: composed_sim against ARGoS's runs (tests/fidelity/data/).

  python tools/fidelity/table.py            the code as it is
  python tools/fidelity/table.py --before   the same code with what issue #29 changed put back:
      the e-puck's evenly spaced proximity ring (22.5° + 45°·i), every proximity sensor element
      read by the robot's own calibration (the e-puck's quadratic for ARGoS's generic sensor), the
      controllers' answer to tick 0 driving the first step, and the foot-bot without its gripper body
  python tools/fidelity/table.py --regions 2 [--border-contacts ignore]   the physics in regions
      (worker processes, docs/fidelity.md "Regions")
"""
from __future__ import annotations

import argparse
import math
import sys
from dataclasses import replace
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
from composed_sim.hosts import tick_loop  # noqa: E402 - after the checkout is put on sys.path
from composed_sim.world import robot_models  # noqa: E402 - after the checkout is put on sys.path
from tests.fidelity import reference  # noqa: E402 - after the checkout is put on sys.path
from tests.fidelity.compare import compare  # noqa: E402 - after the checkout is put on sys.path


def as_before() -> None:
    """Put back what #29 changed (this process only)."""
    epuck = robot_models.MODELS["e-puck"]
    ring = replace(epuck.proximity, angles_rad=tuple(math.radians(22.5 + 45.0 * i) for i in range(8)))
    robot_models.MODELS["e-puck"] = replace(epuck, layouts={**epuck.layouts, "proximity": ring})
    robot_models.MODELS["foot-bot"] = replace(robot_models.MODELS["foot-bot"], carried_mass_kg=0.0,
                                              carried_moment_kg_m2=0.0)
    tick_loop.acted_commands = lambda tick, commands: commands


def own_calibration(world):
    (group,) = world.robots
    proximity = group.devices.proximity
    devices = (group.devices.model_copy(update={"proximity": proximity.model_copy(update={"model": None})})
               if proximity is not None else group.devices)
    data = world.model_dump()
    data["robots"][0]["devices"] = devices.model_dump()
    return type(world).model_validate(data)


def in_regions(count: int, border_contacts: str):
    def edit(world):
        physics = world.physics.model_copy(update={"regions": count, "border_contacts": border_contacts})
        return world.model_copy(update={"physics": physics})
    return edit


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--before", action="store_true")
    p.add_argument("--experiments", nargs="*", default=list(reference.EXPERIMENTS))
    p.add_argument("--regions", type=int, default=1)
    p.add_argument("--border-contacts", choices=("ghosts", "ignore"), default="ghosts")
    args = p.parse_args()
    edit = lambda world: world  # noqa: E731 - the identity edit, one expression
    if args.before:
        as_before()
        edit = own_calibration
    if args.regions > 1:
        edit = in_regions(args.regions, args.border_contacts)
    print("| example | seeds | metric | tick | ARGoS | composed_sim | gap |")
    print("|---|---|---|---|---|---|---|")
    worst_rows = []
    for name in args.experiments:
        for label, seeds in (("suite", reference.SEEDS if name in reference.MAIN else None),
                             ("held out", reference.HELD_OUT.get(name, reference.VARIANT_SEEDS))):
            if seeds is None:
                continue
            result = compare(name, seeds, edit=edit)
            rows = list(result.rows())
            for tick, metric, theirs, ours, gap in rows:
                print(f"| {name} | {label} {seeds[0]}–{seeds[-1]} | {metric} | {tick} | {theirs:.4g} | "
                      f"{ours:.4g} | {gap:.2f} |")
            worst = max(rows, key=lambda r: r[-1])
            worst_rows.append((name, label, worst))
            sys.stdout.flush()
    print()
    print("| example | seeds | worst gap | where |")
    print("|---|---|---|---|")
    for name, label, (tick, metric, theirs, ours, gap) in worst_rows:
        print(f"| {name} | {label} | {gap:.2f} | {metric} at {tick} ({theirs:.4g} against {ours:.4g}) |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
