"""How a process hosts its nodes: the choices and their defaults, for the command line and the
benchmark too, and what every process of a run is told of them (imports no rclpy)."""
from __future__ import annotations

import argparse
from dataclasses import dataclass
from typing import Optional

DEBUG, INFO, WARN, ERROR, FATAL = 10, 20, 30, 40, 50          # rclpy's LoggingSeverity values
LEVELS = {"debug": DEBUG, "info": INFO, "warn": WARN, "error": ERROR}

EXECUTORS = ("lockstep", "events", "single-threaded", "multi-threaded")
DEFAULT_EXECUTOR = EXECUTORS[0]
# Composed mode in one process: robots per DDS participant (hosting/participant_groups.py). Set-up
# costs about this × N; each participant costs its threads and ports: docs/speed.md has the
# measurements.
ROBOTS_PER_PARTICIPANT = 80


@dataclass(frozen=True)
class LogSettings:
    """Where the nodes' log lines go, as the command line asked (hosting/guard/node_logs.py); picklable,
    for worker and controller processes."""
    log_dir: Optional[str] = None       # None: no files (the lines still reach the console)
    console_level: int = WARN
    rosout: bool = False                # keep every line for /rosout in the recording

    @property
    def node_level(self) -> int:
        """The nodes' default level: INFO as in ROS, DEBUG when the console asks for it."""
        return min(INFO, self.console_level)


@dataclass(frozen=True)
class ProcessHosting:
    """How a process hosts its robots' nodes: the same in every process of a run but for the
    domain (multi-process mode spreads them). A worker process gets it with its block (pickled),
    a controller process on its command line (``argv``, read back by ``from_args``)."""
    executor: str = DEFAULT_EXECUTOR
    domain_id: int = 0
    logs: Optional[LogSettings] = None      # where the nodes' log lines go; None: rclpy's loggers

    @property
    def lockstep(self) -> bool:
        """Is the nodes' executor the host's own, which it walks (not one of rclpy's, kept for comparison)?"""
        return self.executor == "lockstep"

    def argv(self) -> list[str]:
        args = ["--domain", str(self.domain_id), "--executor", self.executor]
        if self.logs is not None and self.logs.log_dir:
            args += ["--log-dir", self.logs.log_dir, "--log-level", str(self.logs.console_level)]
            args += ["--rosout"] if self.logs.rosout else []
        return args

    @staticmethod
    def add_arguments(parser: argparse.ArgumentParser) -> None:
        parser.add_argument("--domain", type=int, required=True, help="ROS domain id")
        parser.add_argument("--executor", default=DEFAULT_EXECUTOR)
        parser.add_argument("--log-dir", default=None, help="write the nodes' log lines to LOG_DIR/<robot>.log")
        parser.add_argument("--log-level", type=int, default=WARN, help="the nodes' console level (a LoggingSeverity)")
        parser.add_argument("--rosout", action="store_true",
                            help="send the nodes' log lines for /rosout to the simulator")

    @classmethod
    def from_args(cls, args: argparse.Namespace) -> "ProcessHosting":
        logs = LogSettings(args.log_dir, args.log_level, rosout=args.rosout) if args.log_dir else None
        return cls(args.executor, args.domain, logs)
