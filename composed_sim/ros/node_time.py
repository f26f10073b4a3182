"""CPU seconds spent inside the nodes' own code, in this process: what the host does not cost.

The benchmark's host cost per robot-tick is the run's CPU time minus this. Two ways to count it:

- **Reading the thread's CPU clock around the node's code**: the callback guard around a plain
  node's callbacks, the ``SwarmController`` base class around its ``on_tick`` only (its decoding
  and answering are the host's). The thread's clock, so that time waiting for a core is not
  counted. Exact, but each read is a system call (in this VM about 0.5 µs in place at 1280
  robots: two per robot-tick were about 1 µs of the host's 31).
- **Sampling the main thread**, where the lockstep walk runs every callback (``sampling_main_thread``,
  while a composed host or a worker serves its ticks): a timer on the main thread's CPU clock,
  signalled to that thread alone, interrupts it about every millisecond of its CPU time (at the
  kernel's tick: every 4 ms on this machine), and the thread's CPU time since the last sample
  counts as the nodes' when the thread is in their code then (``MAIN.inside``, set around it at
  the cost of two attribute writes). An unbiased estimate: the samples fall where the thread
  spends its CPU time, whatever it runs. Its error shrinks with the samples, so the clock is read
  as well until the thread has spent ``WARM_UP_S`` of CPU time under sampling (``MAIN.exact``):
  a short run is counted exactly.

Callbacks on other threads (the multi-threaded executor's) read their thread's clock throughout.
"""
from __future__ import annotations

import contextlib
import ctypes
import signal
import threading
import time
from typing import Iterator, Optional

WARM_UP_S = 2.0            # CPU seconds of the main thread counted exactly before sampling alone
SAMPLE_EVERY_NS = 1_000_000    # asked for; the kernel delivers at its tick (HZ) at the finest

_seconds = 0.0             # read from the clock
_sampled_s = 0.0           # estimated by the samples


class _MainThread:
    """What the sampler reads of the main thread."""
    __slots__ = ("inside", "exact")

    def __init__(self) -> None:
        self.inside = False    # in a node's own code now
        self.exact = True      # the nodes' code reads the clock (no sampler, or still warming up)


MAIN = _MainThread()


def add(seconds: float) -> None:
    global _seconds
    _seconds += seconds


def seconds() -> float:
    return _seconds + _sampled_s


# --- the main thread's sampler -------------------------------------------------------------------

_CLOCK_THREAD_CPUTIME_ID = 3       # <time.h>
_SIGEV_THREAD_ID = 4               # <signal.h>: signal one thread, named by its kernel id


class _SigEvent(ctypes.Structure):           # struct sigevent (Linux, 64-bit): 64 bytes
    _fields_ = [("value", ctypes.c_void_p), ("signo", ctypes.c_int), ("notify", ctypes.c_int),
                ("thread_id", ctypes.c_int), ("_pad", ctypes.c_int * 11)]


class _TimeSpec(ctypes.Structure):
    _fields_ = [("sec", ctypes.c_long), ("nsec", ctypes.c_long)]


class _ITimerSpec(ctypes.Structure):
    _fields_ = [("interval", _TimeSpec), ("value", _TimeSpec)]


def _libc() -> Optional[ctypes.CDLL]:
    """The C library with ``timer_create`` (glibc 2.34 on: libc itself; before: librt)."""
    for name in (None, "librt.so.1"):
        try:
            lib = ctypes.CDLL(name, use_errno=True)
            if hasattr(lib, "timer_create"):
                return lib
        except OSError:
            continue
    return None


class _Sampler:
    def __init__(self, libc: ctypes.CDLL) -> None:
        self._libc = libc
        self._timer = ctypes.c_void_p()
        self._started_cpu = self._last_cpu = 0.0

    def start(self) -> bool:
        event = _SigEvent(signo=signal.SIGPROF, notify=_SIGEV_THREAD_ID, thread_id=threading.get_native_id())
        if self._libc.timer_create(_CLOCK_THREAD_CPUTIME_ID, ctypes.byref(event), ctypes.byref(self._timer)) != 0:
            return False
        self._started_cpu = self._last_cpu = time.thread_time()
        every = _TimeSpec(0, SAMPLE_EVERY_NS)
        if self._libc.timer_settime(self._timer, 0, ctypes.byref(_ITimerSpec(every, every)), None) != 0:
            self._libc.timer_delete(self._timer)
            return False
        return True

    def stop(self) -> None:
        self._libc.timer_delete(self._timer)

    def on_sample(self, signum, frame) -> None:
        global _sampled_s
        now = time.thread_time()
        if MAIN.exact:
            MAIN.exact = now - self._started_cpu < WARM_UP_S
        elif MAIN.inside:
            _sampled_s += now - self._last_cpu
        self._last_cpu = now


@contextlib.contextmanager
def sampling_main_thread() -> Iterator[bool]:
    """While serving ticks whose callbacks run in this, the main, thread: its nodes' time is
    sampled (yields True), once ``WARM_UP_S`` of its CPU time has been counted exactly. Nothing
    changes (False) off the main thread, where SIGPROF has a handler already (a profiler's), or
    without POSIX CPU-time timers."""
    libc = _libc() if threading.current_thread() is threading.main_thread() else None
    if libc is None or signal.getsignal(signal.SIGPROF) not in (signal.SIG_DFL, signal.SIG_IGN):
        yield False
        return
    sampler = _Sampler(libc)
    previous = signal.signal(signal.SIGPROF, sampler.on_sample)
    if not sampler.start():
        signal.signal(signal.SIGPROF, previous)
        yield False
        return
    try:
        yield True
    finally:
        sampler.stop()
        # A sample signalled before the timer went may still be pending: ignoring the signal
        # discards it (its default action would end the process).
        signal.signal(signal.SIGPROF, signal.SIG_IGN)
        signal.signal(signal.SIGPROF, previous)
        MAIN.exact, MAIN.inside = True, False
