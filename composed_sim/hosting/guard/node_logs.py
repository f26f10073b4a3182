"""Hosted nodes' logs and tracebacks: per robot in ``<out>/logs/<robot>.log``, on the console once.

A node written for a process of its own logs with ``self.get_logger().info(…)``, to its stderr.
Hosted by the hundred that would flood the terminal (768 000 lines for 1280 robots × 600 ticks)
and mix every robot's lines. So each hosted node gets a ``NodeLogger`` instead of rclpy's logger
(``node_options.construct`` installs it right after ``Node.__init__``, so the rest of the
constructor logs through it too). It has the ``RcutilsLogger`` interface (levels, children,
``once``/``skip_first``/``throttle_duration_sec``) and hands each line to the process's
``NodeLogs``, which:

- appends it, stamped with sim time and tick, to the robot's log file (run-wide nodes: the
  node's), in memory until ``FLUSH_BYTES`` are pending, at an error, and at the end;
- shows the console the lines at or above its level (``--log-level``, warnings by default), each
  call site of each node class once, and counts the rest for the closing lines;
- keeps them for ``/rosout`` in the recording (``--record``).

A callback's exception goes the same way, whole (``exception``): the traceback into the robot's
file, on the console the first time per node class and exception type, a count after.

In a worker process (hosts/workers/launcher.py) the files are written there, and what the main
process needs goes with each tick's answers (``drain``): the console's first lines, the repeat
counts, the failures, and the lines for /rosout only while recording. A controller process
(multi-process mode) writes its robot's file itself; the main process reads its traceback from
its output (``FAILURE_MARK``).

No rclpy here: the worker host's main process merges without it.
"""
from __future__ import annotations

import functools
import sys
import threading
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Optional, TextIO

from composed_sim.hosting.process_hosting import DEBUG, ERROR, FATAL, INFO, WARN, LogSettings

_NAMES = {DEBUG: "DEBUG", INFO: "INFO", WARN: "WARN", ERROR: "ERROR", FATAL: "FATAL"}
FLUSH_BYTES = 1 << 20          # pending log text over all files before they are written out
FAILURE_MARK = "composed-sim-failure"   # a controller process's line before its traceback


def node_label(cls: type) -> str:
    """How messages name a node class: ``package.module:Class``, as a world file names it."""
    return f"{cls.__module__}:{cls.__qualname__}"


@dataclass
class _Repeats:
    more: int = 0                        # occurrences after the first
    robots: set = field(default_factory=set)
    example: str = ""                    # a robot (or node) whose log has it
    first: str = ""                      # what the closing line quotes


class Console:
    """The console's side: a key's first text printed, its repeats counted for ``closing_lines``."""

    def __init__(self, out: Optional[TextIO] = None, logs_hint: str = "logs"):
        self._out = out
        self.logs_hint = logs_hint       # how the closing lines name the log directory
        self._seen: dict[tuple, _Repeats] = {}

    def note(self, key: tuple, owner: str, text: str, first: str = "") -> bool:
        """``text`` (first time for ``key``, printed) or a repeat; True the first time. ``first``:
        what the closing line quotes."""
        seen = self._seen.get(key)
        if seen is None:
            self._seen[key] = _Repeats(0, {owner}, owner, first)
            print(text, file=self._out or sys.stderr, flush=True)
            return True
        seen.more += 1
        seen.robots.add(owner)
        return False

    def repeated(self, key: tuple, more: int, owners: set) -> None:
        """Repeats counted elsewhere (a worker process)."""
        seen = self._seen.setdefault(key, _Repeats(0, set(), next(iter(owners), "")))
        seen.more += more
        seen.robots |= owners

    def closing_lines(self) -> list[str]:
        lines = []
        for key, seen in self._seen.items():
            if key[0] == "failure":           # ("failure", node class, exception type)
                others = sorted(seen.robots - {seen.example}, key=lambda r: (len(r), r))
                if others:
                    named = ", ".join(others[:3]) + (", …" if len(others) > 3 else "")
                    lines.append(f"composed-sim: {key[2]} in {key[1]}: {len(others)} more robot"
                                 f"{'s' * (len(others) > 1)} ({named}), see {self.logs_hint}/<robot>.log")
            elif seen.more:
                owners = len(seen.robots)
                times = (f"{seen.more} more time{'s' * (seen.more > 1)} from {owners} robot{'s' * (owners > 1)}")
                if key[0] == "log":            # ("log", node class, level, call site)
                    lines.append(f"composed-sim: [{key[2]}] {key[1]} at {Path(key[3]).name or '?'}: {times} after "
                                 f"{seen.first!r}, see {self.logs_hint}/{seen.example}.log")
                else:                          # ("note", text): a host's line, said once
                    lines.append(f"composed-sim: {key[1]} ({times})")
        return lines

    @property
    def failures(self) -> dict[str, int]:
        """"ZeroDivisionError in pkg.mod:Class" → robots, for summary.json."""
        return {f"{k[2]} in {k[1]}": len(s.robots) for k, s in self._seen.items() if k[0] == "failure"}


def _locked(method):
    """One thread at a time: the nodes log from the multi-threaded executor's threads too."""
    @functools.wraps(method)
    def locked(self, *args, **kwargs):
        with self._lock:
            return method(self, *args, **kwargs)
    return locked


class NodeLogs:
    """One process's hosted-node logs (see the module's docstring). ``forward``: a worker's,
    whose console lines go to the main process with ``drain`` instead of printing."""

    def __init__(self, settings: LogSettings, tick_ns: int, *, forward: bool = False,
                 console: Optional[Console] = None):
        self.settings = settings
        self.tick_ns = tick_ns
        self.tick = -1                              # set by the host as each tick opens; -1: set-up
        self.clock: Optional[Callable[[], int]] = None   # sim ns, where no host sets the tick
        self._dir = Path(settings.log_dir) if settings.log_dir else None
        if self._dir is not None:
            self._dir.mkdir(parents=True, exist_ok=True)
        self.console = console if console is not None else Console(logs_hint=str(self._dir or "logs"))
        self._forward = forward
        self._buffers: dict[str, list[str]] = {}
        self._lock = threading.RLock()
        self._pending = 0
        self.lines = 0                              # log lines written (all levels)
        self.rosout: list[tuple] = []               # (stamp ns, level, logger name, text, file, function, line)
        self._first: list[tuple] = []               # forwarded: (key, owner, text) printed first in the main process
        self._repeats: dict[tuple, list] = {}       # forwarded: key → [more, owners]
        self._console_keys: set = set()

    # --- what hosted nodes call ---------------------------------------------------------------

    def logger(self, owner: str, cls: type, name: str) -> "NodeLogger":
        """The logger of a node of class ``cls`` named ``name`` (rclpy's logger name) whose lines
        go to ``<owner>.log``."""
        return NodeLogger(self, owner, node_label(cls), name)

    def now(self) -> tuple[int, int]:
        """(tick, sim ns) of the line being logged."""
        if self.clock is not None:
            ns = self.clock()
            return ns // self.tick_ns, ns
        return self.tick, max(self.tick, 0) * self.tick_ns

    @_locked
    def emit(self, owner: str, label: str, name: str, level: int, message: str, site: Optional[tuple]) -> None:
        tick, ns = self.now()
        stamp = f"sim {ns / 1e9:.3f} s, tick {tick}" if tick >= 0 else "set-up"
        self._append(owner, f"[{_NAMES.get(level, level)}] [{stamp}] [{name}]: {message}\n")
        if level >= self.settings.console_level:
            # Once per node class and call site: its text often differs per robot and tick.
            where = f"{site[0]}:{site[2]}" if site else message
            self._to_console(("log", label, _NAMES.get(level, str(level)), where), owner,
                             f"[{_NAMES.get(level, level)}] [{name}] ({label}, {stamp}): {message}",
                             message if len(message) <= 80 else message[:77] + "...")
        if self.settings.rosout:
            file, function, line = site or ("", "", 0)
            self.rosout.append((ns, level, name, message, file, function, line))
        if level >= ERROR:
            self.flush()

    @_locked
    def exception(self, owner: str, cls: type, name: str, error: BaseException, skip: str = "") -> None:
        """A callback's exception, which fails robot ``owner``: the traceback (frames of files
        whose path ends with ``skip`` left out: the host's wrapper) to its log and the console."""
        tick, ns = self.now()
        stamp = f"sim {ns / 1e9:.3f} s, tick {tick}" if tick >= 0 else "set-up"
        if getattr(error, "an_end", False):        # the node ended its own process: no fault, no traceback
            self._append(owner, f"[INFO] [{stamp}] [{name}]: {error}\n")
            self._to_console(("end", str(error)), owner, f"composed-sim: {owner}: {error} (tick {tick})")
            return
        text = format_traceback(error, skip)
        self._append(owner, f"[ERROR] [{stamp}] [{name}]: callback raised {type(error).__name__}; "
                            f"{owner} is failed\n{text}")
        self.flush()
        self.failure(owner, node_label(cls), type(error).__name__, tick, text)
        if self.settings.rosout:
            self.rosout.append((ns, ERROR, name, text.rstrip(), "", "", 0))

    @_locked
    def failure(self, owner: str, label: str, kind: str, tick: int, text: str) -> None:
        """A robot failed by ``kind`` (an exception type) raised in a node of class ``label``."""
        where = f"{self.console.logs_hint}/{owner}.log"
        self._to_console(("failure", label, kind), owner,
                         f"composed-sim: {owner}: a node ({label}) raised {kind} at tick {tick}; the robot is "
                         f"failed (its log: {where}):\n{text.rstrip()}")

    @_locked
    def note(self, owner: str, text: str) -> None:
        """A line of the host's for the console, once per text (in a worker: by the main process)."""
        self._to_console(("note", text), owner, f"composed-sim: {text}")

    # --- the console, here or in the main process ---------------------------------------------

    def _to_console(self, key: tuple, owner: str, text: str, first: str = "") -> None:
        if not self._forward:
            self.console.note(key, owner, text, first)
        elif key not in self._console_keys:
            self._console_keys.add(key)
            self._first.append((key, owner, text, first))
        else:
            entry = self._repeats.setdefault(key, [0, set()])
            entry[0] += 1
            entry[1].add(owner)

    @property
    def forwarding(self) -> bool:
        """Has a forwarding process anything for the main process (``drain``)?"""
        return bool(self._first or self._repeats or self.rosout)

    @_locked
    def drain(self) -> tuple:
        """A worker's part for the main process since the last drain: (first lines, repeats, rosout)."""
        out = (self._first, [(k, n, owners) for k, (n, owners) in self._repeats.items()], self.rosout)
        self._first, self._repeats, self.rosout = [], {}, []
        return out

    @_locked
    def merge(self, drained: tuple) -> None:
        """The main process: a worker's ``drain``."""
        first, repeats, rosout = drained
        for key, owner, text, quoted in first:
            self.console.note(key, owner, text, quoted)
        for key, more, owners in repeats:
            self.console.repeated(key, more, owners)
        self.rosout.extend(rosout)

    # --- files ---------------------------------------------------------------------------------

    def _append(self, owner: str, text: str) -> None:
        self.lines += 1
        if self._dir is None:
            return
        buffer = self._buffers.get(owner)
        if buffer is None:
            buffer = self._buffers[owner] = []
        buffer.append(text)
        self._pending += len(text)
        if self._pending >= FLUSH_BYTES:
            self.flush()

    @_locked
    def write(self, owner: str, text: str) -> None:
        """Text for ``owner``'s log as it is (a controller process's traceback, read by the host)."""
        self._append(owner, text if text.endswith("\n") else text + "\n")
        self.flush()

    @_locked
    def flush(self) -> None:
        """Append what is pending to the files (opened and closed each time: thousands of robots
        would exceed the open-file limit). No fsync: a crash of the machine may lose the tail."""
        for owner, lines in self._buffers.items():
            if lines:
                with open(self._dir / f"{owner}.log", "a", encoding="utf-8", errors="replace") as f:
                    f.writelines(lines)
                lines.clear()
        self._pending = 0


def raising_node(error: BaseException, nodes) -> Optional[object]:
    """The node among ``nodes`` whose method the traceback went through last (where a callback
    of an executor's raised), or None."""
    found, tb = None, error.__traceback__
    ids = {id(n) for n in nodes}
    while tb is not None:
        owner = tb.tb_frame.f_locals.get("self")
        if id(owner) in ids:
            found = owner
        tb = tb.tb_next
    return found


def format_traceback(error: BaseException, skip: str = "") -> str:
    """The exception's traceback as Python prints it, without the leading frames of files whose
    path contains one of ``skip``'s comma-separated parts (the host's, rclpy's executor)."""
    tb, parts = error.__traceback__, [p for p in skip.split(",") if p]
    while parts and tb is not None and tb.tb_next is not None \
            and any(p in tb.tb_frame.f_code.co_filename.replace("\\", "/") for p in parts):
        tb = tb.tb_next
    return "".join(traceback.format_exception(type(error), error, tb))


class NodeLogger:
    """What a hosted node's ``get_logger()`` returns: rclpy's ``RcutilsLogger`` interface, its
    lines to ``NodeLogs``. A line below the level costs one comparison."""

    def __init__(self, logs: NodeLogs, owner: str, label: str, name: str, parent: Optional["NodeLogger"] = None):
        self._logs, self._owner, self._label, self.name = logs, owner, label, name
        self._parent = parent
        self._level = 0                      # UNSET: the parent's, or the run's default
        self.contexts: dict = {}             # per call site, for rclpy's filters

    def get_child(self, name: str) -> "NodeLogger":
        if not name:
            raise ValueError("Child logger name must not be empty.")
        return NodeLogger(self._logs, self._owner, self._label, f"{self.name}.{name}", self)

    def set_level(self, level) -> None:
        self._level = int(level)

    def host_note(self, text: str) -> None:
        """A line of the host's about this node, for the console once per text (not for its log,
        which holds what the node itself said)."""
        self._logs.note(self._owner, text)

    def get_effective_level(self):
        from rclpy.logging import LoggingSeverity
        return LoggingSeverity(self._effective())

    def _effective(self) -> int:
        if self._level:
            return self._level
        return self._parent._effective() if self._parent is not None else self._logs.settings.node_level

    def is_enabled_for(self, severity) -> bool:
        return int(severity) >= self._effective()

    def log(self, message, severity, **kwargs) -> bool:
        severity = int(severity)
        if severity < (self._level or (self._parent._effective() if self._parent is not None
                                       else self._logs.settings.node_level)):
            return False
        name = kwargs.pop("name", self.name)
        site = None
        if kwargs:
            from rclpy.impl.rcutils_logger import CallerId, get_filters_from_kwargs, supported_filters
            filters = get_filters_from_kwargs(**kwargs)
            caller = CallerId(sys._getframe(1) if sys._getframe(1).f_code.co_filename != __file__
                              else sys._getframe(2))
            context = self.contexts.get(caller)
            if context is None:
                context = self.contexts[caller] = {"name": name, "severity": severity, "filters": filters}
                for f in filters:
                    supported_filters[f].initialize_context(context, **kwargs)
            if not all(supported_filters[f].should_log(context) for f in context["filters"]):
                return False
            site = (caller.file_path, caller.function_name, caller.line_number)
        if site is None and (severity >= self._logs.settings.console_level or self._logs.settings.rosout):
            frame = sys._getframe(1)
            if frame.f_code.co_filename == __file__:      # through info(), warn(), …
                frame = frame.f_back
            site = (frame.f_code.co_filename, frame.f_code.co_name, frame.f_lineno)
        self._logs.emit(self._owner, self._label, name, severity, str(message), site)
        return True

    def debug(self, message, **kwargs) -> bool:
        return self.log(message, DEBUG, **kwargs)

    def info(self, message, **kwargs) -> bool:
        return self.log(message, INFO, **kwargs)

    def warning(self, message, **kwargs) -> bool:
        return self.log(message, WARN, **kwargs)

    warn = warning

    def error(self, message, **kwargs) -> bool:
        return self.log(message, ERROR, **kwargs)

    def fatal(self, message, **kwargs) -> bool:
        return self.log(message, FATAL, **kwargs)


def failure_from_output(output: str) -> Optional[tuple[str, str, int, str]]:
    """A controller process's output → (node class, exception type, tick, traceback) after its
    ``FAILURE_MARK`` line (``FAILURE_MARK <class> <type> <tick>``), or None."""
    at = output.rfind(FAILURE_MARK + " ")
    if at < 0:
        return None
    head, _, rest = output[at:].partition("\n")
    words = head.split()
    if len(words) < 4 or not words[3].lstrip("-").isdigit():
        return None
    start = rest.find("Traceback (most recent call last)")
    text = rest[start:] if start >= 0 else rest
    lines = [ln for ln in text.splitlines() if "\x1b[" not in ln]
    return words[1], words[2], int(words[3]), "\n".join(lines).strip() + "\n"
