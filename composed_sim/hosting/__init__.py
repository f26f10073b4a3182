"""Node hosting: rclpy nodes by the hundred in one process, each given what its own process would
have given it, run in lockstep ticks. This module is the package's front door: the hosts and the
tools above import what they use from here (an import-linter contract keeps it so), and each
name is loaded when first asked for, so that a light caller (the command line's choices) loads
no rclpy.

Inside, by job:

- ``hosted_block.py``: the one way a block of nodes on one executor is hosted, used by every place
  that hosts nodes; ``participant_groups.py``: a process's block of robots in DDS participants that
  ignore one another, with their simulator nodes, and the tick's exchange (``nodes_exchange.py``);
- ``building/``: a robot's nodes (and the run-wide ones) built from the world file with the options
  of their own process, checked against the topic contract; lifecycle nodes brought up;
- ``executors/``: the lockstep executor (or one of rclpy's) and how it is driven while a tick is open;
- ``calls/``: services, clients, actions and parameters between nodes, places, processes;
- ``run_wide/``: the topics outside every robot's namespace, relayed at one point of the tick;
- ``sim_time/``: the nodes' timers, rates and sleeps on sim time;
- ``guard/``: a robot's faulty callback stays that robot's fault; the nodes' log lines; their CPU time;
- ``dds/``: the participants' discovery among themselves, the simulator's endpoints, and Fast DDS's
  files in /dev/shm of processes that are gone.

Below it, ``ros/`` holds the topic contract, the simulator node and the in-process delivery;
above it, ``hosts/`` holds the tick loop and the host modes that use all this.
"""
from importlib import import_module


class HostError(Exception):
    """The host cannot start: the message says what and why."""


class ContractViolation(Exception):
    """A hosted node made what the topic contract does not allow it to."""


# What the hosts and tools may use, by the module that defines it (relative to this package).
_EXPORTS = {
    # how a process hosts its nodes: the choices and their defaults (no rclpy)
    "process_hosting": ("ProcessHosting", "EXECUTORS", "DEFAULT_EXECUTOR", "ROBOTS_PER_PARTICIPANT", "LogSettings",
                        "LEVELS", "WARN"),
    # blocks of nodes and the tick's exchange with their simulator nodes
    "hosted_block": ("HostedBlock",),
    "participant_groups": ("ParticipantGroups",),
    "nodes_exchange": ("NodesExchange", "RelayingExchange"),
    # building a robot's nodes
    "building.nodes": ("create_robot_nodes", "load_classes", "before_node_imports", "node_field"),
    "building.wiring": ("published_answer_type",),
    # executors and how they are driven
    "executors.lockstep": ("LockstepExecutor",),
    "executors.idle": ("readings_waiting",),
    "executors.running": ("Spinning", "make_executor", "check_executor", "driven_by_caller", "run_until_idle",
                          "shut_down"),
    # calls between places, and their rounds across processes
    "calls.between_places": ("CallRelay", "Request", "handover_order", "RUN_WIDE_ORIGIN"),
    "calls.rounds": ("Rounds", "PipeRounds", "replies", "routed", "send_to_live", "worker_places"),
    # run-wide topics
    "run_wide.relay": ("RunWideRelay", "Message", "is_run_wide"),
    "run_wide_nodes": ("RunWideNodes", "create_run_wide_nodes", "first_timer_tick_of", "wait_for_run_wide_timers"),
    # the drones' Crazyswarm2 endpoints and the crazyflie_server
    "drones": ("ProcessDrones", "has_run_wide_nodes", "flying_robots"),
    "run_wide.link": ("RunWideLink", "SimulatorLink"),
    "sim_time.timers": ("before_each_tick", "clocks_to"),
    # the nodes' logs and failures
    "guard.node_logs": ("NodeLogs", "Console", "FAILURE_MARK", "failure_from_output",
                        "node_label", "raising_node"),
    "guard.callback_guard": ("end_process_on_thread_shutdown",),
    # DDS: participants, shared memory, matched endpoints
    "dds.participants": ("ignore_participants_of_this_process", "run_prefix", "use_worker_prefix"),
    "dds.shared_memory": ("remove_stale_shared_memory", "remove_own_shared_memory"),
    "dds.matching": ("matched", "matched_count", "publishes", "contract_endpoints", "poll_until"),
}
_MODULE_OF = {name: module for module, names in _EXPORTS.items() for name in names}
__all__ = ["HostError", "ContractViolation", *_MODULE_OF]


def __getattr__(name: str):
    module = _MODULE_OF.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(import_module(f"{__name__}.{module}"), name)
    globals()[name] = value          # asked once
    return value
