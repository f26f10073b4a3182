"""What composed mode's flocking ticks cost in rclpy calls alone: the floor under the ticks.

Per robot and tick, the composed host makes these rclpy calls on the flocking world: the
simulator node asks proximity's matched count (nobody reads it) and publishes the robot's
``light`` and ``blobs``; the controller takes both and publishes its ``cmd_vel``; the simulator
node takes that. This runs exactly those calls, as serialized bytes of the flocking world's
message sizes, over participants of ``ROBOTS_PER_PARTICIPANT`` robots as the composed host
makes them, and nothing else: no decoding, no controller arithmetic, no executor, no physics.
Whatever the simulator and the controllers do in Python comes on top of it.

    python -m composed_sim.bench.rclpy_floor --robots 80,1280 [--ticks 100] [--blobs 50] [--robots-per-participant K|all]
"""
from __future__ import annotations

import argparse
import json
import time

import numpy as np

from composed_sim.hosting import ignore_participants_of_this_process, ROBOTS_PER_PARTICIPANT
from composed_sim.hosts.settings import environment_domain

WARM_UP_TICKS = 10


def measure(robots: int, ticks: int, *, blobs: int = 50, domain_id: int = 0,
            robots_per_participant: int = ROBOTS_PER_PARTICIPANT) -> float:
    """µs per robot-tick of the exchange's rclpy calls for ``robots`` robots over ``ticks`` ticks
    (each robot seeing ``blobs`` blobs). Call it in a process of its own: it creates participants."""
    ignore_participants_of_this_process()
    import rclpy
    from rclpy.context import Context
    from rclpy.node import Node

    from composed_sim.world.robot_models import FOOTBOT
    from composed_sim.ros import contract as c
    from composed_sim.devices import camera, light as light_ring
    from composed_sim.ros.robot_settings import quiet_node_options

    light = light_ring.encoder(FOOTBOT.light, "bot0").encode(1, 0, np.zeros(len(FOOTBOT.light.angles_rad)))
    blob_cloud = camera.encoder("bot0").encode(1, 0, bytes(camera.BLOB_DTYPE.itemsize * blobs), blobs)
    answer = c.answer_encoder().encode(1, 0, 0.1, 0.2)
    contexts, exchange = [], []
    try:
        for start in range(0, robots, robots_per_participant):
            context = Context()
            rclpy.init(context=context, domain_id=domain_id)
            contexts.append(context)
            sim = Node("floor_simulator", context=context, **quiet_node_options())
            for r in range(start, min(robots, start + robots_per_participant)):
                controller = Node("floor_controller", namespace=f"/bot{r}", context=context, **quiet_node_options())
                exchange.append(_endpoints(sim, controller, f"bot{r}"))
        while not all(p.get_subscription_count() for row in exchange for p in (row[1], row[2], row[5])):
            time.sleep(0.01)

        def tick() -> None:
            for proximity, light_pub, blobs_pub, *_ in exchange:
                proximity.get_subscription_count()
                light_pub.publish(light)
                blobs_pub.publish(blob_cloud)
            for _, _, _, light_sub, blobs_sub, answer_pub, _ in exchange:
                _take(light_sub)
                _take(blobs_sub)
                answer_pub.publish(answer)
            for *_, answer_sub in exchange:
                _take(answer_sub)

        for _ in range(WARM_UP_TICKS):
            tick()
        t0 = time.perf_counter()
        for _ in range(ticks):
            tick()
        return 1e6 * (time.perf_counter() - t0) / (ticks * robots)
    finally:
        for context in contexts:
            rclpy.shutdown(context=context)


def _endpoints(sim, controller, robot: str) -> tuple:
    """(proximity, light and blobs publishers; the controller's light and blobs subscriptions and
    cmd_vel publisher; the simulator's cmd_vel subscription) of one robot, as the hosts make them."""
    from composed_sim.ros import contract as c
    topic = {t.name: c.topic_name(robot, t) for t in (c.PROXIMITY, c.LIGHT, c.BLOBS, c.CMD_VEL)}
    return (sim.create_publisher(c.msg_type(c.PROXIMITY), topic["proximity"], c.QOS),
            sim.create_publisher(c.msg_type(c.LIGHT), topic["light"], c.QOS),
            sim.create_publisher(c.msg_type(c.BLOBS), topic["blobs"], c.QOS),
            controller.create_subscription(c.msg_type(c.LIGHT), topic["light"], _ignore, c.QOS, raw=True),
            controller.create_subscription(c.msg_type(c.BLOBS), topic["blobs"], _ignore, c.QOS, raw=True),
            controller.create_publisher(c.msg_type(c.CMD_VEL), topic["cmd_vel"], c.QOS),
            sim.create_subscription(c.msg_type(c.CMD_VEL), topic["cmd_vel"], _ignore, c.QOS, raw=True))


def _ignore(_msg) -> None:
    pass


def _take(subscription) -> None:
    with subscription.handle:
        if subscription.handle.take_message(subscription.msg_type, True) is None:
            raise RuntimeError(f"nothing to take on {subscription.topic_name}: delivery inside a participant "
                               f"is synchronous, so the floor would not be what composed mode does")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m composed_sim.bench.rclpy_floor", description=__doc__.split("\n\n")[0])
    parser.add_argument("--robots", default="80,1280", help="comma-separated swarm sizes (default: %(default)s)")
    parser.add_argument("--ticks", type=int, default=100, help="timed ticks per size (default: %(default)s)")
    parser.add_argument("--blobs", type=int, default=50, help="blobs each robot sees (default: %(default)s, "
                                                              "the flocking world's mean at 1280 robots)")
    parser.add_argument("--robots-per-participant", default=str(ROBOTS_PER_PARTICIPANT),
                        help="robots per DDS participant, or 'all' for one participant (a worker process's "
                             "case; default: %(default)s, the single-process host's)")
    parser.add_argument("--domain-id", type=int, default=None, help="default: $ROS_DOMAIN_ID or 0")
    args = parser.parse_args(argv)
    domain_id = args.domain_id if args.domain_id is not None else environment_domain() or 0
    for n in (int(v) for v in args.robots.split(",")):
        per = n if args.robots_per_participant == "all" else int(args.robots_per_participant)
        us = measure(n, args.ticks, blobs=args.blobs, domain_id=domain_id, robots_per_participant=per)
        print(json.dumps({"robots": n, "robots_per_participant": per, "ticks": args.ticks, "blobs": args.blobs, "us_per_robot_tick": round(us, 1),
                          "s_per_600_ticks": round(600 * n * us * 1e-6, 1)}), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
