"""Measuring one run as a whole process tree: wall time, CPU, peak RSS and PSS (psutil), with a
timeout that stops the run at a tick first and kills what is left after."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import tempfile
import time
from dataclasses import dataclass
from typing import Optional

SAMPLE_S = 0.15             # psutil sampling period of a run's process tree
PSS_SAMPLE_S = 1.0          # PSS reads each process's smaps: sampled less often
TERM_GRACE_S = 15.0         # after SIGTERM (timeout), time to stop at a tick and write, then SIGKILL
LEFTOVER_GRACE_S = 10.0     # time a run's descendants get to exit after its root did
STDERR_TAIL_CHARS = 600


@dataclass
class TreeMeasurement:
    exit_code: Optional[int]
    wall_s: float
    cpu_core_s: float                 # the whole tree, see measure_tree
    root_cpu_s: float                 # the root process alone
    peak_tree_rss_kb: int             # peak of the summed RSS of the tree
    peak_root_rss_kb: int
    peak_others_rss_kb: int           # peak of the summed RSS of every process but the root
    max_processes: int                # most processes alive in the tree at one sample
    stdout: str
    stderr: str
    peak_tree_pss_kb: int = 0         # peak of the summed PSS of the tree (sampled every PSS_SAMPLE_S)
    peak_others_pss_kb: int = 0
    timed_out: bool = False
    interrupted: bool = False
    leftovers_killed: int = 0         # descendants still alive LEFTOVER_GRACE_S after the root exited
    other_cores: Optional[float] = None  # machine-wide busy CPU outside the tree / wall


class _Tracked:
    __slots__ = ("proc", "cpu_s")

    def __init__(self, proc):
        self.proc = proc
        self.cpu_s = 0.0


class _TreeSampler:
    """Samples a process tree: each process's last CPU time, and the peaks of RSS, PSS and of the
    number of processes alive."""

    def __init__(self, root):
        self.root = root
        self.tracked: dict[int, _Tracked] = {root.pid: _Tracked(root)}
        self.retired: list[_Tracked] = []      # processes whose pid was reused by a later one
        self.peak_tree = self.peak_root = self.peak_others = 0
        self.peak_pss = self.peak_others_pss = 0
        self.max_processes = 0
        self._next_pss = 0.0

    def sample(self, root_alive: bool) -> None:
        import psutil
        with_pss = time.perf_counter() >= self._next_pss
        if with_pss:
            self._next_pss = time.perf_counter() + PSS_SAMPLE_S
        root = self.root
        procs = []
        if root_alive:
            try:
                procs = [root] + root.children(recursive=True)
            except psutil.Error:
                procs = [root]
        else:
            procs = [t.proc for t in self.tracked.values() if t.proc is not root]
        rss_root = rss_others = alive = pss_root = pss_others = 0
        for p in procs:
            t = self.tracked.get(p.pid)
            if t is None or t.proc is not p and not _same_process(t.proc, p):
                if t is not None:
                    self.retired.append(t)
                t = self.tracked[p.pid] = _Tracked(p)
            try:
                with t.proc.oneshot():
                    times = t.proc.cpu_times()
                    rss = t.proc.memory_info().rss
                pss = t.proc.memory_full_info().pss if with_pss else 0
            except psutil.Error:
                continue
            t.cpu_s = max(t.cpu_s, times.user + times.system)
            if rss:
                alive += 1
            if t.proc is root:
                rss_root, pss_root = rss, pss
            else:
                rss_others += rss
                pss_others += pss
        self.peak_root = max(self.peak_root, rss_root)
        self.peak_others = max(self.peak_others, rss_others)
        self.peak_tree = max(self.peak_tree, rss_root + rss_others)
        self.peak_pss = max(self.peak_pss, pss_root + pss_others)
        self.peak_others_pss = max(self.peak_others_pss, pss_others)
        self.max_processes = max(self.max_processes, alive)

    def end_leftovers(self, grace_s: float, sample_s: float) -> tuple[int, float]:
        """Descendants that outlived the root (orphans, which its times cannot hold): given
        ``grace_s``, then ended. (How many were killed, their CPU seconds.)"""
        root = self.root
        leftovers = [t.proc for t in self.tracked.values() if t.proc is not root and _alive(t.proc)]
        orphan_pids = {p.pid for p in leftovers}
        deadline = time.perf_counter() + grace_s
        while leftovers and time.perf_counter() < deadline:
            self.sample(root_alive=False)
            time.sleep(sample_s)
            leftovers = [p for p in leftovers if _alive(p)]
        if leftovers:
            _kill_all(leftovers)
            _wait_gone(leftovers, 5.0)
        return len(leftovers), sum(t.cpu_s for pid, t in self.tracked.items() if pid in orphan_pids)

    @property
    def sampled_cpu_s(self) -> float:
        return sum(t.cpu_s for t in [*self.tracked.values(), *self.retired])


def measure_tree(cmd: list[str], *, env: dict, timeout_s: float, sample_s: float = SAMPLE_S,
                 leftover_grace_s: float = LEFTOVER_GRACE_S) -> TreeMeasurement:
    """Run ``cmd`` and watch its process tree until it and every descendant are gone.

    CPU: each process's last sampled user+system time is kept (so processes that exit between
    samples still count up to their last sample); the root is detected at exit without being
    reaped (waitid WNOWAIT), its final own and reaped-children times read, then it is reaped with
    wait4. cpu_core_s = max(root's own + reaped descendants' exact times + last samples of
    descendants that outlived it, sum of last samples of everything): both are lower bounds of
    the truth, the first exact unless some descendant was never waited for by its parent."""
    import psutil

    with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err:
        busy0 = _machine_busy_s()
        t0 = time.perf_counter()
        proc = subprocess.Popen(cmd, stdout=out, stderr=err, stdin=subprocess.DEVNULL, env=env)
        tree = _TreeSampler(psutil.Process(proc.pid))
        timed_out, interrupted = _watch(proc, tree, t0, timeout_s, sample_s)
        wall_s = time.perf_counter() - t0
        busy1 = _machine_busy_s()
        exit_code, root_own, exact, max_rss_kb = _reap_root(proc, tree)
        leftovers_killed, orphans_cpu = tree.end_leftovers(leftover_grace_s, sample_s)
        out.seek(0)
        err.seek(0)
        stdout = out.read().decode(errors="replace")
        stderr = err.read().decode(errors="replace")
    peak_tree = max(tree.peak_tree, max_rss_kb * 1024)   # a run shorter than a sample period
    cpu_core_s = max(exact + orphans_cpu, tree.sampled_cpu_s)
    other = None
    if busy0 is not None and busy1 is not None and wall_s > 0:
        other = max(busy1 - busy0 - cpu_core_s, 0.0) / wall_s
    return TreeMeasurement(
        exit_code=exit_code, wall_s=wall_s, cpu_core_s=cpu_core_s, other_cores=other,
        root_cpu_s=max(root_own, tree.tracked[proc.pid].cpu_s),
        peak_tree_rss_kb=peak_tree // 1024, peak_root_rss_kb=tree.peak_root // 1024,
        peak_others_rss_kb=tree.peak_others // 1024, max_processes=tree.max_processes,
        peak_tree_pss_kb=tree.peak_pss // 1024, peak_others_pss_kb=tree.peak_others_pss // 1024,
        stdout=stdout, stderr=stderr, timed_out=timed_out, interrupted=interrupted,
        leftovers_killed=leftovers_killed)


def _watch(proc: subprocess.Popen, tree: _TreeSampler, t0: float, timeout_s: float,
           sample_s: float) -> tuple[bool, bool]:
    """Sample the tree until its root has exited (seen without reaping it). Past ``timeout_s`` the
    root gets SIGTERM, and the whole tree SIGKILL TERM_GRACE_S later; Ctrl-C ends the run the same
    way. (Timed out, interrupted.)"""
    root = tree.root
    timed_out = interrupted = False
    term_sent_at: Optional[float] = None
    try:
        while os.waitid(os.P_PID, proc.pid, os.WEXITED | os.WNOHANG | os.WNOWAIT) is None:
            tree.sample(root_alive=True)
            elapsed = time.perf_counter() - t0
            if term_sent_at is None and elapsed > timeout_s:
                timed_out, term_sent_at = True, elapsed
                _signal(root, signal.SIGTERM)      # the run stops at the next tick and writes
            elif term_sent_at is not None and elapsed > term_sent_at + TERM_GRACE_S:
                _kill_all(t.proc for t in tree.tracked.values())
            time.sleep(sample_s)
    except KeyboardInterrupt:
        interrupted = True
        _signal(root, signal.SIGTERM)
        if not _wait_exit(proc.pid, TERM_GRACE_S / 3):
            _kill_all(t.proc for t in tree.tracked.values())
    return timed_out, interrupted


def _reap_root(proc: subprocess.Popen, tree: _TreeSampler) -> tuple[int, float, float, int]:
    """The exited root's final times read, then reaped with wait4: (exit code, its own CPU
    seconds, the exact CPU seconds of it and the descendants it reaped, its peak RSS in kB)."""
    import psutil
    # The root is a zombie now: its own times are final, and so are those of the descendants
    # it reaped (children_*), which wait4's rusage covers too.
    root_own = root_children = 0.0
    try:
        ct = tree.root.cpu_times()
        root_own, root_children = ct.user + ct.system, ct.children_user + ct.children_system
    except psutil.Error:
        pass
    _, status, usage = os.wait4(proc.pid, 0)
    proc.returncode = exit_code = os.waitstatus_to_exitcode(status)
    tree.tracked[proc.pid].cpu_s = max(tree.tracked[proc.pid].cpu_s, root_own)
    exact = max(usage.ru_utime + usage.ru_stime, root_own + root_children)
    return exit_code, root_own, exact, usage.ru_maxrss


def _wait_exit(pid: int, timeout_s: float) -> bool:
    """Wait until our child ``pid`` has exited, without reaping it (psutil's wait would)."""
    deadline = time.perf_counter() + timeout_s
    while os.waitid(os.P_PID, pid, os.WEXITED | os.WNOHANG | os.WNOWAIT) is None:
        if time.perf_counter() > deadline:
            return False
        time.sleep(0.05)
    return True


def _machine_busy_s() -> Optional[float]:
    """Core-seconds the whole machine has spent busy since boot (not idle, waiting or stolen)."""
    import psutil
    try:
        t = psutil.cpu_times()
    except Exception:    # noqa: BLE001 - psutil's errors differ by platform; no figure is the answer
        return None
    return sum(getattr(t, k, 0.0) for k in ("user", "nice", "system", "irq", "softirq"))


def _same_process(a, b) -> bool:
    try:
        return a.create_time() == b.create_time()
    except Exception:    # noqa: BLE001 - a process gone or hidden meanwhile is not the same one
        return False


def _alive(p) -> bool:
    import psutil
    try:
        return p.is_running() and p.status() != psutil.STATUS_ZOMBIE
    except psutil.Error:
        return False


def _signal(p, sig) -> None:
    import psutil
    try:
        if p.is_running():            # checks the pid still names the process we started
            p.send_signal(sig)
    except psutil.Error:
        pass


def _kill_all(procs) -> None:
    for p in list(procs):
        _signal(p, signal.SIGKILL)


def _wait_gone(procs, timeout_s: float) -> None:
    """Wait for processes that are not our children (psutil would reap a child)."""
    import psutil
    try:
        psutil.wait_procs([p for p in procs if _alive(p)], timeout=timeout_s)
    except psutil.Error:
        pass


def parse_summary(stdout: str) -> Optional[dict]:
    """The JSON object that ``run --json`` prints last on stdout, or None."""
    text = stdout.strip()
    starts = [i for i in range(len(text)) if text[i] == "{" and (i == 0 or text[i - 1] == "\n")]
    for i in reversed(starts):
        try:
            obj, end = json.JSONDecoder().raw_decode(text, i)
        except ValueError:
            continue
        if isinstance(obj, dict) and not text[end:].strip():
            return obj
    return None


def tail(text: str, limit: int = STDERR_TAIL_CHARS, max_lines: int = 8) -> str:
    """The last lines of a run's stderr on one line (CSV-friendly)."""
    lines = [ln.strip() for ln in text.replace("\r", "\n").splitlines() if ln.strip()][-max_lines:]
    joined = " | ".join(lines)
    return ("…" + joined[-limit:]) if len(joined) > limit else joined
