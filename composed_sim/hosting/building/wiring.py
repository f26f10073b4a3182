"""Whether a robot's nodes can answer its ticks, checked against the topic contract: what they
publish and subscribe to, the type of their answers, and the publishers they make later."""
from __future__ import annotations

from typing import Collection, Container, Mapping, Optional, Sequence

from rclpy.node import Node

from composed_sim.hosting import ContractViolation
from composed_sim.hosting.building.lifecycle import is_active
from composed_sim.hosting.run_wide.relay import RunWideRelay
from composed_sim.ros import contract as c
from composed_sim.world.robot_models import get_model
from composed_sim.world.schema import RobotGroup, World


def guard_publishers(node: Node, robot: str, robots: Container[str], answer_type: Optional[type],
                     robot_nodes: Sequence[Node]) -> None:
    """Make ``node.create_publisher`` refuse another robot's topic, a sensor topic or a wrong
    type on its own actuator topic (``contract.publisher_problem``; on cmd_vel: another type than its
    answers have, ``answer_type`` or the one of the first cmd_vel publisher of the robot's nodes): the
    fault is the publishing robot's, found where it starts, and no other robot ever receives a
    foreign answer."""
    create = node.create_publisher

    def create_publisher(msg_type, topic, *args, **kwargs):
        problem = c.publisher_problem(robot, node.resolve_topic_name(topic), msg_type, robots,
                                      answer_type or published_answer_type(robot_nodes, robot))
        if problem is not None:
            raise ContractViolation(problem)
        return create(msg_type, topic, *args, **kwargs)
    node.create_publisher = create_publisher


def robot_sensor_topics(group: RobotGroup, name: str) -> list[str]:
    """Robot ``name``'s sensor topics (resolved), as its group's devices publish them."""
    return [c.topic_name(name, t) for t in c.robot_topics(group.devices.published(get_model(group.model)))
            if t.direction == "sensor"]


def answer_rule(world: World, group_index: int, name: str, nodes: Sequence[Node],
                relay: Optional[RunWideRelay]) -> tuple[Optional[str], bool]:
    """When robot ``name``'s nodes answer its ticks, one rule for every host mode: ``(problem,
    later)``. A problem refuses the robot before tick 0: its nodes could never answer (a
    subscription to a topic it does not have, a cmd_vel of another type than the world file's,
    or no cmd_vel publisher where nothing could make one). ``later``: none of its nodes publishes
    cmd_vel (or reads its sensors) yet, but one may: a lifecycle node not active yet (its
    transitions make its entities), or a group whose robots answer when published (a node may
    make its publisher in a callback). Such a robot keeps its last command until its first
    answer, as a robot's base does (ros/answer_ledger.py). A drone's firmware answers its ticks:
    its nodes (if any) need neither cmd_vel nor a sensor, only the topics they read must be its."""
    group = world.robots[group_index]
    sensors = robot_sensor_topics(group, name)
    run_wide = {t for node in nodes for t in relay.topics_published_by(node)} if relay is not None else set()
    problem, silent = wiring_problem(nodes, name, sensors, run_wide)
    if get_model(group.model).flies:
        return (None if silent else problem), False
    problem = problem or answer_type_problem(nodes, name, group.cmd_vel)
    if problem is None:
        return None, False
    may_later = group.answers == "when_published" or any(not is_active(node) for node in nodes)
    if silent and may_later:
        return None, True
    if silent:
        problem += ("; if a node makes its publisher later (in a callback), say answers: when_published in "
                    "the robot's group; a lifecycle node not active yet is waited for")
    return problem, False


def wiring_problem(nodes: Sequence[Node], robot: str, sensors: Sequence[str],
                   run_wide: Collection[str] = ()) -> tuple[Optional[str], bool]:
    """Why a robot's nodes cannot answer its ticks, found as soon as they are built: no node
    publishes its cmd_vel, none subscribes to one of its sensor topics, or one subscribes to a
    robot topic that nobody publishes (a sensor its model lacks, a misspelt name). The message
    names what the robot has and the closest name; with it, whether the nodes are only silent
    (no cmd_vel publisher or sensor subscription yet), which a node may mend later.
    ``run_wide``: the topics outside the robots' namespaces the nodes publish
    (hosting/run_wide/relay.py)."""
    published = {p.topic_name for node in nodes for p in node.publishers} | set(run_wide)
    subscribed = [(node, s.topic_name, s.msg_type) for node in nodes for s in node.subscriptions]
    sensor_types = {t: c.msg_type(c.TOPICS[t.rsplit("/", 1)[1]]) for t in sensors}
    own = f"/{robot}/"
    for node, topic, msg_type in subscribed:
        if not topic.startswith(own) or topic in sensor_types or topic in published:
            continue
        name = topic[len(own):]
        close = _closest(name, [t[len(own):] for t in sensor_types], msg_type,
                         {t[len(own):]: ty for t, ty in sensor_types.items()})
        if name in c.TOPICS or close is not None:
            return (f"node {node.get_fully_qualified_name()} subscribes to {topic}, which {robot} does not have "
                    f"(its sensor topics: {', '.join(sensors) or 'none'}){f'; did you mean {close}?' if close else ''}",
                    False)
    cmd_vel = c.topic_name(robot, c.CMD_VEL)
    if cmd_vel not in published:
        tails = {t.rsplit("/", 1)[1]: t for t in sorted(published, reverse=True)}
        close = _closest(c.CMD_VEL.name, list(tails), None, {})
        return (f"none of {robot}'s nodes publishes {cmd_vel}, the robot's answer to each tick (they publish: "
                f"{', '.join(sorted(published)) or 'nothing'})"
                f"{f'; remap {tails[close]} to cmd_vel?' if close else ''}", True)
    if not any(topic in sensor_types for _, topic, _ in subscribed):
        return (f"none of {robot}'s nodes subscribes to one of its sensor topics ({', '.join(sensors)}); they "
                f"subscribe to: {', '.join(sorted({t for _, t, _ in subscribed})) or 'nothing'}", True)
    return None, False


def _closest(name: str, candidates: Sequence[str], msg_type: Optional[type], types: Mapping[str, type]) -> Optional[str]:
    """The candidate closest to ``name`` in spelling, else the only one of the same message type."""
    import difflib
    close = difflib.get_close_matches(name, candidates, n=1, cutoff=0.6)
    if close:
        return close[0]
    same_type = [t for t in candidates if msg_type is not None and types.get(t) is msg_type]
    return same_type[0] if len(same_type) == 1 else None


def published_answer_type(nodes: Sequence[Node], robot: str) -> Optional[type]:
    """The type of the first publisher on the robot's cmd_vel among ``nodes``, None without one."""
    topic = c.topic_name(robot, c.CMD_VEL)
    return next((p.msg_type for node in nodes for p in node.publishers if p.topic_name == topic), None)


def answer_type(nodes: Sequence[Node], robot: str, declared: str) -> Optional[type]:
    """What ``robot``'s answers will be: the world file's ``cmd_vel`` type (stamped, unstamped),
    else (auto) its nodes' publisher's, else None: not known yet (a publisher created later)."""
    return c.ANSWER_TYPES[declared] if declared != "auto" else published_answer_type(nodes, robot)


def answer_type_problem(nodes: Sequence[Node], robot: str, declared: str) -> Optional[str]:
    """The world file's ``cmd_vel`` (stamped, unstamped) against what the nodes publish."""
    found = published_answer_type(nodes, robot)
    if declared == "auto" or found is None or found is c.ANSWER_TYPES[declared]:
        return None
    return (f"it publishes {c.type_name(found)} on {c.topic_name(robot, c.CMD_VEL)}, but the world file says "
            f"cmd_vel: {declared} ({c.type_name(c.ANSWER_TYPES[declared])})")
