"""A process's drones on the ROS side (docs/crazyflie.md): the Crazyswarm2 endpoints of each of its
blocks of drones, beside the block's simulator node (ros/crazyflie/endpoints.py), served as the
block's nodes' services are (hosting/hosted_block.py); the run-wide ``crazyflie_server``
(ros/crazyflie/server.py) where the run-wide nodes are; and the commands they took in the tick
(ros/crazyflie/outbox.py), which the host takes at the tick's close and carries to the main
process, where the firmware runs (core/drone_commands.py).
"""
from __future__ import annotations

from typing import Callable, Optional, Sequence

from rclpy.context import Context

from composed_sim.core.drone_commands import DroneCommand
from composed_sim.core.placement import place_robots
from composed_sim.core.seeding import STREAM_PLACEMENT, stream
from composed_sim.hosting.executors.lockstep import LockstepExecutor
from composed_sim.hosting.executors.running import run_until_idle
from composed_sim.hosting.hosted_block import HostedBlock
from composed_sim.ros.crazyflie import messages
from composed_sim.ros.crazyflie.endpoints import DroneEndpoints
from composed_sim.ros.crazyflie.outbox import DroneOutbox
from composed_sim.ros.crazyflie.server import NAME as SERVER_NAME, CrazyflieServer, find, server_parameters
from composed_sim.ros.rcl_graph import GraphChanges
from composed_sim.world.crazyflies import crazyflies
from composed_sim.world.robot_models import get_model
from composed_sim.world.robot_groups import NodeSpec
from composed_sim.world.schema import World

SERVER_NODE = f"{CrazyflieServer.__module__}:{CrazyflieServer.__name__}"


def flying_robots(world: World) -> list[bool]:
    """Per robot: does it fly (its firmware answers its ticks: never waited for)?"""
    flies = [get_model(g.model).flies for g in world.robots]
    return [flies[g] for g in world.group_of_robot()]


def has_run_wide_nodes(world: World) -> bool:
    """Has the run run-wide nodes: the world's, or the crazyflie_server of its drones?"""
    return bool(world.nodes) or any(flying_robots(world))


def run_wide_specs(world: World) -> list[NodeSpec]:
    """The world's run-wide nodes, and the ``crazyflie_server`` of a world with drones."""
    drones = crazyflies(world)
    if not drones:
        return list(world.nodes)
    positions, _ = place_robots(world, stream(world.seed, STREAM_PLACEMENT))
    return [*world.nodes, NodeSpec(node=SERVER_NODE, parameters=server_parameters(drones, positions))]


def with_server_class(world: World, classes: dict) -> dict:
    return {**classes, SERVER_NODE: CrazyflieServer} if crazyflies(world) else classes


class ProcessDrones:
    """The drones of the blocks this process hosts."""

    def __init__(self, world: World):
        self.roster = crazyflies(world)             # the run's drones
        self._tick_ns = world.tick_ns
        self._interfaces: Optional[messages.Interfaces] = None     # loaded once the world's packages are active
        self.outbox = DroneOutbox()
        self.endpoints: list[DroneEndpoints] = []
        self._watches: list[Callable[[], bool]] = []   # per endpoints: has its participant's graph changed?
        # Where the host's threads spin the simulator's nodes (multi-process mode): an executor per
        # endpoints, driven by the tick's thread (``serve_alone``).
        self._alone: list[tuple[LockstepExecutor, HostedBlock]] = []
        self._graphs: list[GraphChanges] = []

    @property
    def interfaces(self) -> Optional[messages.Interfaces]:
        """Crazyswarm2's interface classes (None without drones, or where they are not built: the
        crazyflie_server says so, once)."""
        if self._interfaces is None and self.roster:
            self._interfaces = messages.load()
            if self._interfaces is None:
                self.roster = []
        return self._interfaces

    def make_endpoints(self, context: Context, robots: Sequence[int], node_name: str,
                       frame_start: int = 0) -> Optional[DroneEndpoints]:
        """The endpoints of the drones among ``robots``, in ``context`` (their simulator node's),
        or None without any."""
        if self.interfaces is None:
            return None
        wanted = set(robots)
        mine = [d for d in self.roster if d.robot in wanted]
        if not mine:
            return None
        battery = get_model("crazyflie").flight.battery_full_v
        endpoints = DroneEndpoints(context, mine, self.interfaces, self.outbox, node_name=f"{node_name}_crazyflies",
                                   tick_ns=self._tick_ns, battery_v=battery, frame_start=frame_start)
        self.endpoints.append(endpoints)
        return endpoints

    @property
    def nodes(self) -> list:
        """The nodes that serve the drones' services, for the block's executor."""
        return [e.node for e in self.endpoints]

    def host(self, block) -> None:
        """Each drone's services served by ``block`` (a HostedBlock) as its nodes' are."""
        for endpoints in self.endpoints:
            block.serve(endpoints.node, endpoints.services())

    def attach_server(self, run_wide_nodes) -> None:
        """The run-wide ``crazyflie_server``, if this process hosts it: its commands go to this
        process's outbox."""
        server = find(run_wide_nodes.nodes) if run_wide_nodes is not None else None
        if server is not None:
            server.attach(self.outbox, {d.name: d.robot for d in self.roster})

    def watch(self, graph_changed: Sequence[Callable[[], bool]]) -> None:
        """Per endpoints (in order): has its participant's ROS graph changed since the last look?
        Without a watch, each tick looks at the graph."""
        self._watches = list(graph_changed)

    def refresh(self) -> None:
        """Before a tick: the setpoint and status topics that other nodes began to use."""
        for k, endpoints in enumerate(self.endpoints):
            if k >= len(self._watches) or self._watches[k]():
                endpoints.refresh()

    def take(self, published: Optional[dict[str, int]] = None, timeout_s: float = 1.0) -> list[DroneCommand]:
        """At the tick's close: the commands taken in it (the setpoints received since are taken now;
        ``published``: how many were sent on each topic since the start, by processes whose parts are in,
        waited for up to ``timeout_s``)."""
        for endpoints in self.endpoints:
            endpoints.drain(published or {}, timeout_s)
        return self.outbox.take()

    # --- endpoints with an executor of their own (multi-process mode) -------------------------------

    def serve_alone(self, calls, robots: Sequence[str]) -> None:
        """Each endpoints' services served by a lockstep executor of its own, which the host drives
        from the tick's thread (``start_tick``, ``run_until_idle``): ``calls``, the host's call relay
        (hosting/calls/between_places.py), hands them the calls of the run-wide nodes; other
        processes' requests are taken as each tick starts (``robots``: the run's)."""
        for endpoints in self.endpoints:
            graph = GraphChanges([endpoints.inbox])     # the one watch of its participant's graph
            self._graphs.append(graph)
            executor = LockstepExecutor(context=endpoints.node.context)
            executor.add_node(endpoints.node)
            block = HostedBlock(executor, robots=robots, graph_changed=graph.poll(0), calls=calls,
                                places=[d.robot for d in endpoints.drones])
            block.serve(endpoints.node, endpoints.services())
            self._alone.append((executor, block))
        self.watch([graph.poll(0) for graph in self._graphs])

    def graph_changed(self, context: Context) -> Optional[Callable[[], bool]]:
        """Has the ROS graph of ``context``'s participant changed since the last look, as the watch of
        ``serve_alone`` sees it (None: it watches none there)? One watch per participant: a second
        wait on its graph would take the first's triggers."""
        for endpoints, graph in zip(self.endpoints, self._graphs):
            if endpoints.node.context is context:
                return graph.poll(0)
        return None

    @property
    def places(self) -> frozenset[int]:
        """The drones whose services this process serves (their places, for the calls between places)."""
        return frozenset(d.robot for endpoints in self.endpoints for d in endpoints.drones)

    def start_tick(self) -> None:
        """Before the tick's sensors: the setpoint topics begun since, other processes' calls served."""
        self.refresh()
        for executor, block in self._alone:
            block.start_tick()
            run_until_idle(executor)

    def run_until_idle(self) -> None:
        """The calls handed over to the drones' services, served."""
        for executor, _ in self._alone:
            run_until_idle(executor)

    def destroy(self) -> None:
        for executor, block in self._alone:
            block.close()
            executor.shutdown()
        for graph in self._graphs:
            graph.close()
        self._alone, self._graphs = [], []
        for endpoints in self.endpoints:
            endpoints.destroy()
        self.endpoints = []


__all__ = ["ProcessDrones", "SERVER_NAME", "flying_robots", "has_run_wide_nodes", "run_wide_specs", "with_server_class"]
