"""Child processes of a run (multi-process controllers, worker processes): they never outlive it.

Light on purpose: a child imports this first, before rclpy, to tie its life to its parent's.
"""
from __future__ import annotations

import ctypes
import os
import signal
import subprocess
import sys
import threading
import time

PR_SET_PDEATHSIG = 1
PR_SET_CHILD_SUBREAPER = 36


def die_with_parent(parent_pid: int | None, sig: int = signal.SIGTERM) -> None:
    """``sig`` to this process when its parent dies (any way, SIGKILL included). Done first, before
    the slow imports; the getppid check covers a parent that died between our fork and the prctl."""
    if sys.platform.startswith("linux"):
        libc = ctypes.CDLL(None, use_errno=True)
        if libc.prctl(PR_SET_PDEATHSIG, sig, 0, 0, 0) != 0:
            print(f"prctl(PR_SET_PDEATHSIG) failed: errno {ctypes.get_errno()}", file=sys.stderr)
    if parent_pid is not None and os.getppid() != parent_pid:
        sys.exit(0)


def become_subreaper() -> None:
    """This process adopts its orphaned descendants (Linux's PR_SET_CHILD_SUBREAPER): the worker
    processes, forked by a launcher that then exits, become its children, to be waited for and
    signalled like any child (``AdoptedChild``)."""
    libc = ctypes.CDLL(None, use_errno=True)
    if libc.prctl(PR_SET_CHILD_SUBREAPER, 1, 0, 0, 0) != 0:
        raise OSError(ctypes.get_errno(), "prctl(PR_SET_CHILD_SUBREAPER) failed")


class AdoptedChild:
    """A child this process did not start itself (forked by a launcher, then adopted: see
    ``become_subreaper``), with the part of ``subprocess.Popen`` the hosts use: ``pid``,
    ``returncode``, ``poll``, ``wait``."""

    def __init__(self, pid: int):
        self.pid = pid
        self.returncode: int | None = None

    def poll(self) -> int | None:
        if self.returncode is None:
            pid, status = os.waitpid(self.pid, os.WNOHANG)
            if pid:
                self.returncode = os.waitstatus_to_exitcode(status)
        return self.returncode

    def wait(self, timeout: float | None = None) -> int:
        if timeout is None:
            if self.returncode is None:
                self.returncode = os.waitstatus_to_exitcode(os.waitpid(self.pid, 0)[1])
            return self.returncode
        deadline = time.monotonic() + timeout
        delay = 0.0005
        while self.poll() is None:      # as Popen.wait(timeout) does: no waitpid with a timeout
            left = deadline - time.monotonic()
            if left <= 0:
                raise subprocess.TimeoutExpired(f"pid {self.pid}", timeout)
            time.sleep(min(delay, left))
            delay = min(delay * 2, 0.05)
        return self.returncode


def exit_reason(code: int) -> str:
    """A Popen return code in words: "process killed by SIGSEGV", "process exited with code 3"."""
    if code < 0:
        try:
            return f"process killed by {signal.Signals(-code).name}"
        except ValueError:
            return f"process killed by signal {-code}"
    return f"process exited with code {code}"


def last_words(log_tail: str) -> str:
    """A child's last line of its own (a plugin's exception, usually), as ": line", or "". Fast
    DDS's own log lines (coloured, e.g. about stale shared-memory ports) are not the child's."""
    lines = [ln.strip() for ln in log_tail.splitlines() if ln.strip() and "\x1b[" not in ln]
    return f": {lines[-1]}" if lines else ""


def signal_group(popen, sig: int) -> None:
    """``sig`` to a child started with ``process_group=0`` and whatever it started; only while it is
    unreaped (a reaped child's pid may belong to another process by now)."""
    if popen.returncode is None:
        try:
            os.killpg(popen.pid, sig)
        except ProcessLookupError:
            pass


def reap(popens, grace_s: float) -> None:
    """Give the children ``grace_s`` in all to end by themselves, SIGKILL the groups of those left,
    and reap every one."""
    deadline = time.monotonic() + grace_s
    for popen in popens:
        try:
            popen.wait(timeout=max(0.0, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            pass
    for popen in popens:
        signal_group(popen, signal.SIGKILL)
    for popen in popens:
        popen.wait()


class InterruptWatch:
    """Notices SIGINT/SIGTERM during a start-up (minutes for hundreds of children) and still
    hands them to whoever handled them before: the CLI then stops at the next tick (here: before
    tick 0) and writes its results, Python's default handler raises KeyboardInterrupt. Only the
    main thread can install handlers; elsewhere nothing changes."""

    def __init__(self):
        self.requested = False
        self._old: dict = {}

    def __enter__(self) -> "InterruptWatch":
        if threading.current_thread() is threading.main_thread():
            for sig in (signal.SIGINT, signal.SIGTERM):
                old = signal.getsignal(sig)
                if old is not None:            # None: not installed from Python, leave it alone
                    self._old[sig] = old
                    signal.signal(sig, self._handle)
        return self

    def _handle(self, signum, frame) -> None:
        self.requested = True
        old = self._old[signum]
        if callable(old):
            old(signum, frame)
        elif old == signal.SIG_DFL:           # what would have happened: die (children follow)
            signal.signal(signum, signal.SIG_DFL)
            os.kill(os.getpid(), signum)

    def __exit__(self, *exc) -> None:
        for sig, old in self._old.items():
            signal.signal(sig, old)
