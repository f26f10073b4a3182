"""What the world file says per robot, in the form the simulator node takes it, and the node
options of every node a host creates by the thousand."""
from __future__ import annotations

from typing import Optional, Sequence

from rclpy.parameter import Parameter
from rclpy.type_description_service import START_TYPE_DESCRIPTION_SERVICE_PARAM

from composed_sim.ros import contract as c
from composed_sim.world.robot_models import get_model
from composed_sim.world.schema import World


def robot_devices(world: World) -> list[tuple[str, ...]]:
    """Per robot of ``world`` (in robot order): the devices whose topics it has."""
    published = [g.devices.published(get_model(g.model)) for g in world.robots]
    return [published[g] for g in world.group_of_robot()]


def robot_settings(world: World, rows: Sequence[int]) -> dict[str, list]:
    """The SimulatorNode keyword arguments that the world file gives per robot, for the robots
    ``rows``: devices, declared answer types, answers_every_ticks, global_tf, answers_when_published,
    answers_by_firmware."""
    per_robot = {"devices": robot_devices(world), "answer_types": declared_answer_types(world),
                 "answers_every_ticks": answers_every_ticks(world), "global_tf": global_tf(world),
                 "answers_when_published": answers_when_published(world),
                 "answers_by_firmware": answers_by_firmware(world)}
    return {key: [values[i] for i in rows] for key, values in per_robot.items()}


def declared_answer_types(world: World) -> list[Optional[type]]:
    """Per robot: the cmd_vel type its group's world-file entry declares, None for "auto"."""
    declared = [c.ANSWER_TYPES.get(g.cmd_vel) for g in world.robots]
    return [declared[g] for g in world.group_of_robot()]


def global_tf(world: World) -> list[bool]:
    """Per robot: whether its group's tf goes to /tf and /tf_static (``tf: {topics: global}``)."""
    per_group = [g.devices.tf is not None and g.devices.tf.topics == "global" for g in world.robots]
    return [per_group[g] for g in world.group_of_robot()]


def answers_when_published(world: World) -> list[bool]:
    """Per robot: does its group answer only when its nodes publish (``answers: when_published``)?"""
    return [world.robots[g].answers == "when_published" for g in world.group_of_robot()]


def answers_by_firmware(world: World) -> list[bool]:
    """Per robot: does its firmware answer its ticks (a model that flies, core/flight.py)?"""
    flies = [get_model(g.model).flies for g in world.robots]
    return [flies[g] for g in world.group_of_robot()]


def answers_every_ticks(world: World) -> list[int]:
    """Per robot: its group's ``answers_every_ticks``."""
    return [world.robots[g].answers_every_ticks for g in world.group_of_robot()]


def quiet_node_options(parameter_overrides: Sequence[Parameter] = ()) -> dict:
    """Node options for thousands of nodes: no parameter services, no /rosout and no
    ~/get_type_description service. Each would add endpoints, and every new endpoint is
    announced to the whole participant, so node creation would grow quadratically."""
    return dict(start_parameter_services=False, enable_rosout=False,
                parameter_overrides=[*parameter_overrides,
                                     Parameter(START_TYPE_DESCRIPTION_SERVICE_PARAM, value=False)])
