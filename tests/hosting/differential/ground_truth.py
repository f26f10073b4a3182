"""The ground truth: a batch's programs in processes of their own under rclpy, driven tick by tick.

Each robot's nodes run in a process of their own and all run-wide nodes in one more
(``plain_process.py``: rclpy's ``MultiThreadedExecutor``, ``use_sim_time``), as the programs'
own ``main()``s would run them. The rig here plays the simulator: it publishes ``/clock`` and
each robot's ``proximity`` (a LaserScan stamped with the tick's time), and nothing else.

A process gives no signal that it is done with a tick, so the rig makes each tick's work
well-defined by waiting:

1. before tick 0, until every process is built and its clients see the servers that exist from
   the start (``@@READY``), every construction-time scan subscription and every node's /clock
   subscription matched the rig's publishers, and ``QUIET_S`` passed without an event line;
2. tick k: publish ``/clock`` = k ticks to the robots' processes, wait until each says all its
   nodes' clocks read k (``@@CLOCK``, from jump callbacks), then the same to the run-wide
   process (its /clock is remapped), then publish the scans. So whatever reaches a node in tick
   k finds its clock at k, as when all processes hear one /clock at once; only a call between
   two nodes of one robot's process made by a timer (which fires as its own node's clock moves)
   may reach the other node a moment before its clock callback ran;
3. wait until no process logged an event for ``QUIET_S`` (and at least ``QUIET_S`` after the
   scans): what is still to happen then waits for a later time on the clock. Every event line
   read while tick k is open belongs to tick k.

What rclpy defines and what it does not (and so how ``events.py`` compares):

- defined: the order of one callback's own statements, a coroutine's steps across its awaits,
  a done callback after its future completed, a goal's feedback in the order published, a
  service's response after its request was served; the tick at which a timer fires (rcl's timer
  on the ROS clock: due when the clock reaches its next call time; a time jump over several
  periods fires it once; ``Client.call(timeout_sec)`` waits on wall time, so a generated program
  never lets a timeout expire); what a parameter read returns when no set of it is in flight;
- not defined: the order of different callbacks within a tick (sensor callback before or after
  a timer of the same tick, two requests from two places, the scan before the timers: the hosts
  fix one order, rclpy's executor takes whatever is ready): compared as sets per tick; how many
  of a goal's last feedbacks, sent right before its result, its client hears (rclpy's client
  drops those it takes after the result; hosted, it hears them all: ``events.compare``);
- not modelled (generated programs avoid them): a callback of a node's default group that waits
  across ticks (rclpy's /clock subscription is in that group: the node's clock would stop, its
  sleeps never end; the hosts set clocks directly), a blocking call from a mutually exclusive
  group that must take its own response (a deadlock in any process; the hosts refuse it), calls
  to services another process creates after the start (DDS discovery has no tick), topics
  outside the robots (the hosts deliver them a tick later on purpose, as ARGoS's media), and
  ``time.sleep`` (wall time: the rig waits for quiet, not for the wall clock).
- the hosts fire a timer made before tick 0 at tick 0 as well; rclpy one period later (its clock
  read 0 when it was made): the interpreter's timers do nothing when their clock reads 0.

A process that raises (a callback's exception) ends; its nodes' events stop there, as a hosted
robot's stop when the host fails it.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

from differential.events import RunResult
from differential.spec import TICK_NS, places

QUIET_S = 0.3               # no event line for this long: the tick's work is done
READY_TIMEOUT_S = 120.0     # start-up of every process (rclpy imports, discovery) on a loaded machine
CLOCK_TIMEOUT_S = 10.0
HERE = Path(__file__).resolve().parent


class Rig:
    """The processes of one batch and the rig's node: ``/clock`` and each robot's scan."""

    def __init__(self, programs: list[dict], ticks: int, workdir: Path, domain: int):
        self.programs, self.ticks, self.domain = programs, ticks, domain
        self.result = RunResult("rclpy")
        self.tick = -1
        self.lock = threading.Lock()
        self.last_event = time.monotonic()
        self.ready: set[str] = set()
        self.clock: dict[str, int] = {}
        self.places = places(programs)
        self.file = workdir / "places.json"
        self.file.write_text(json.dumps({name: entries for name, entries in self.places}))
        self.processes: dict[str, subprocess.Popen] = {}

    # --- processes ---------------------------------------------------------------------------

    def start(self) -> None:
        env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(HERE.parent), os.environ.get("PYTHONPATH")])),
               "RCUTILS_CONSOLE_OUTPUT_FORMAT": "{message}", "RCUTILS_LOGGING_BUFFERED_STREAM": "0",
               "ROS_DOMAIN_ID": str(self.domain)}
        for name, _ in self.places:
            p = subprocess.Popen([sys.executable, "-m", "differential.plain_process", str(self.file), name,
                                  str(self.domain)], stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                                 stderr=subprocess.PIPE, text=True, env=env)
            self.processes[name] = p
            for stream in (p.stdout, p.stderr):
                threading.Thread(target=self._read, args=(name, stream), daemon=True).start()

    def _read(self, place: str, stream) -> None:
        for line in stream:
            with self.lock:
                if self.result.add_line(line, self.tick):
                    self.last_event = time.monotonic()
                elif line.startswith("@@CLOCK "):
                    self.clock[place] = int(line.split()[1])
                elif line.startswith("@@READY"):
                    self.ready.add(place)
                elif line.startswith("@@FAILED "):
                    self._failed(place, line.split()[1])
                    self.last_event = time.monotonic()

    def _failed(self, place: str, what: str) -> None:
        if place == "run_wide":
            for i, p in enumerate(self.programs):
                for n in p.get("run_wide", ()):
                    self.result.fail(i, n["name"], self.tick, what)
        else:
            i, j = place[1:].split("r")
            self.result.fail(int(i), f"r{j}", self.tick, what)

    def stop(self) -> None:
        for p in self.processes.values():
            if p.poll() is None:
                p.terminate()
        for p in self.processes.values():
            try:
                p.wait(timeout=10)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()

    # --- the ticks -----------------------------------------------------------------------------

    def wait(self, done, timeout: float, what: str) -> bool:
        deadline = time.monotonic() + timeout
        while not done():
            if time.monotonic() > deadline:
                self.result.notes.append(f"tick {self.tick}: gave up waiting for {what}")
                return False
            dead = [n for n, p in self.processes.items() if p.poll() is not None and n not in self.ready]
            if dead and what == "the processes' start":
                self.result.notes.append(f"process {dead[0]} ended before it was ready")
                return False
            time.sleep(0.005)
        return True

    def quiet(self, since: float) -> None:
        while True:
            now = time.monotonic()
            with self.lock:
                last = max(self.last_event, since)
            if now - last >= QUIET_S:
                return
            time.sleep(min(0.02, QUIET_S - (now - last) + 0.001))

    def run(self) -> RunResult:
        from differential.rig_node import RigNode
        with RigNode(self.domain, [name for name, _ in self.places if name != "run_wide"]) as node:
            self.start()
            self.wait(lambda: len(self.ready) == len(self.places), READY_TIMEOUT_S, "the processes' start")
            self.wait(lambda: node.matched(self.expected_scans(), self.node_count("run_wide")), READY_TIMEOUT_S,
                      "the scan and /clock subscriptions")
            self.quiet(time.monotonic())
            for tick in range(self.ticks):
                with self.lock:
                    self.tick = tick
                for run_wide in (False, True):
                    node.publish_clock(tick * TICK_NS, run_wide)
                    if tick:
                        self.wait(lambda: self.clocks_at(tick, run_wide), CLOCK_TIMEOUT_S, "the nodes' clocks")  # noqa: B023 - waited for here
                node.publish_scans(tick * TICK_NS)
                self.quiet(time.monotonic())
        self.stop()
        return self.result

    def clocks_at(self, tick: int, run_wide: bool) -> bool:
        return all(self.clock.get(n, 0) >= tick * TICK_NS for n, p in self.processes.items()
                   if (n == "run_wide") == run_wide and p.poll() is None)

    def expected_scans(self) -> dict[str, int]:
        return {name: sum(1 for _, spec, _ in entries for e in spec.get("entities", ())
                          if e["kind"] == "scan" and not e.get("configured"))
                for name, entries in self.places if name != "run_wide"}

    def node_count(self, place: str) -> tuple[int, int]:
        """The nodes of the robots' processes, and of ``place``."""
        return (sum(len(e) for n, e in self.places if n != place), sum(len(e) for n, e in self.places if n == place))


def run_ground_truth(programs: list[dict], ticks: int, workdir: Path, domain: int) -> RunResult:
    rig = Rig(programs, ticks, workdir, domain)
    try:
        return rig.run()
    finally:
        rig.stop()
