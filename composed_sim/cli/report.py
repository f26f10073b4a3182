"""What ``composed-sim run`` prints: the progress (a bar on a terminal, a line every few seconds
elsewhere) and the summary, for people or as JSON."""
from __future__ import annotations

import contextlib
import json
import os
import shutil
import sys
from pathlib import Path
from typing import Optional


WATCHING_DOC = 'docs/contract.md, "Watching a run from another process"'


def watch_hint(domain_id: int, *, foxglove: bool, markers: bool) -> str:
    """How to watch a run with what this machine has: the pip-only install has rclpy but no
    ``ros2`` command (ros2cli is not on PyPI), so ``ros2`` is named only where it is on PATH;
    an option this run already has is not offered again."""
    now = [f"an rclpy process with ROS_DOMAIN_ID={domain_id} ({WATCHING_DOC})"]
    if shutil.which("ros2"):
        now.append(f"ROS_DOMAIN_ID={domain_id} ros2 topic list")
    options = [] if foxglove else ["--foxglove (the Foxglove app, no ROS install needed)"]
    options += [] if markers else ["--markers (the scene on /swarm/markers)"]
    return f"to watch it: {' or '.join(now)}" + (f"; or run with {' and '.join(options)}" if options else "")


def print_summary(json_stdout: Optional[JsonStdout], world, summary: dict, files: list[str]) -> None:
    """The summary: as JSON on stdout where ``json_stdout`` is given (--json), else for people."""
    if json_stdout is not None:
        with json_stdout.restored():
            print(json.dumps(summary, indent=2), flush=True)
    else:
        from composed_sim.loop_functions import describe
        metrics = summary.get("metrics") or {}
        print(_human_summary(summary, files, describe(world, metrics.get("initial", {}), metrics.get("final", {}))))


class JsonStdout:
    """--json: stdout holds the summary only. Fast DDS's C++ logging writes to file descriptor 1
    (e.g. about stale shared-memory ports of a killed run), so a program of its own makes fd 1
    stderr until the summary is printed (``keep``)."""

    def __init__(self) -> None:
        self._fd: Optional[int] = None      # the real stdout, while fd 1 is stderr

    def keep(self) -> None:
        if self._fd is None:
            sys.stdout.flush()
            self._fd = os.dup(1)
            os.dup2(2, 1)

    @contextlib.contextmanager
    def restored(self):
        if self._fd is None:
            yield
            return
        sys.stdout.flush()
        os.dup2(self._fd, 1)
        try:
            yield
        finally:
            sys.stdout.flush()


PROGRESS_LOG_S = 5.0    # without a terminal: a progress line this often at most


def progress_bar(total: int, disabled: bool):
    """tqdm's bar on a terminal; on a log (CI, a file, a pipe) a plain line now and then instead
    of thousands of carriage returns."""
    from tqdm import tqdm
    if disabled or sys.stderr.isatty():
        return tqdm(total=total, unit="tick", file=sys.stderr, disable=disabled, dynamic_ncols=True,
                    desc="simulating")
    return _ProgressLines(total)


class _ProgressLines:
    def __init__(self, total: int):
        import time
        self._clock = time.monotonic
        self.total, self.done = total, 0
        self._start = self._last = self._clock()
        self._said = False

    def update(self, n: int = 1) -> None:
        self.done += n
        now = self._clock()
        if not self._said or now - self._last >= PROGRESS_LOG_S:
            self._said, self._last = True, now
            self._line(now)

    def _line(self, now: float) -> None:
        rate = self.done / max(now - self._start, 1e-9)
        print(f"simulating: {self.done}/{self.total} ticks ({100 * self.done / max(self.total, 1):.0f} %), "
              f"{rate:.1f} tick/s", file=sys.stderr, flush=True)

    def close(self) -> None:
        if self.done and self._last != self._clock():
            self._line(self._clock())


def _workers_text(s: dict) -> str:
    if s.get("mode") == "machines":
        return f" on {s['workers']} machines"
    if not s.get("workers") or s["workers"] == 1:
        return ""
    return f" in {s['workers']} worker processes" + (" (auto)" if s.get("workers_requested") == "auto" else "")


def _phase_line(s: dict) -> str:
    """The main process's tick, by phase (summary.json's phases_per_tick_ms), biggest first."""
    table = dict(s.get("phases_per_tick_ms") or {})
    serial = table.pop("serial", None)
    parts = ", ".join(f"{phase.replace('_', ' ')} {ms:.1f}" for phase, ms in
                      sorted(table.items(), key=lambda kv: -kv[1]) if ms >= 0.05)
    line = f"  per tick (ms): {parts or '–'}" + (f"; serial {serial:.1f}" if serial is not None else "")
    if s.get("host_cost_per_robot_tick_us") is not None:
        line += (f"\n  per robot-tick: host {s['host_cost_per_robot_tick_us']:.1f} µs, "
                 f"nodes' own code {s['node_code_per_robot_tick_us']:.1f} µs")
    return line


def _human_summary(s: dict, files: list[str], metric_lines: list[str] = ()) -> str:
    lines = [
        f"{s['world']}: {s['robots']} robots, {s['ticks']} ticks ({s['sim_time_s']:.1f} s sim time), "
        f"{s['mode']} mode{_workers_text(s)}, {s['executor']} executor"
        + ("  [interrupted]" if s["interrupted"] else ""),
        f"  setup {s['setup_s']:.2f} s, ticks {s['ticks_wall_s']:.2f} s wall, "
        f"real-time factor {s['real_time_factor'] or 0:.2f}, peak RSS {s['peak_rss_mb']:.0f} MB",
        _phase_line(s),
        f"  violations: {s['violations']}",
    ]
    if s.get("failed_robots"):      # one line: how many, why, where to look
        causes = "; ".join(f"{cause}: {n}" for cause, n in (s.get("failed_by") or {}).items())
        # Controllers driven from outside the run (--external-controllers) log in their own processes.
        logs = s.get("logs")
        where = f"{logs}/<robot>.log and violations.csv" if logs and Path(logs).is_dir() else "violations.csv"
        lines.append(f"  controllers failed: {len(s['failed_robots'])} of {s['robots']} robots"
                     f"{f' ({causes})' if causes else ''}; see {where}")
    lines += metric_lines
    if s.get("ended_by_loop_functions"):
        lines.append(f"  ended by the loop functions at tick {s['ticks']}")
    lines.append(f"  results in {s['out']}/ ({', '.join(files)})")     # what this run wrote, no more
    return "\n".join(lines)
