"""Node hosting: rclpy nodes by the hundred in one process, each given what its own process would
have given it, run in lockstep ticks.

- ``building.py``: a robot's nodes (and the run-wide ones) built from the world file with the
  options of their own process (``node_options.py``), their timers on sim time
  (``sim_timers.py``), checked against the topic contract;
- ``executors/``: the executor that runs them (``lockstep.py``, or one of rclpy's) and how it is
  driven: from the calling thread or its own, until every answer is in, until idle;
- ``callback_guard.py``: a robot's faulty callback stays that robot's fault; ``node_logs.py``:
  their log lines and tracebacks; ``node_time.py``: the CPU time of their own code;
- ``participants.py``, ``participant_groups.py``: a block of robots in DDS participants that ignore
  one another, with one executor, and the tick's exchange over their simulator nodes
  (``nodes_exchange.py``);
- ``run_wide/``: the topics outside every robot's namespace, relayed at one point of the tick;
- ``shared_memory.py``: Fast DDS's files in /dev/shm of processes that are gone, removed.

Below it, ``ros/`` holds the topic contract, the simulator node and the in-process delivery;
above it, ``hosts/`` holds the tick loop and the host modes that use all this.
"""


class HostError(Exception):
    """The host cannot start: the message says what and why."""


class ContractViolation(Exception):
    """A hosted node made what the topic contract does not allow it to."""
