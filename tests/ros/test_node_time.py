"""The nodes' own time (ros/node_time.py): read from the thread's clock, or the main thread sampled
by a CPU-time timer of that thread, which counts the time spent where ``MAIN.inside`` is set."""
import signal
import threading
import time

import pytest

from composed_sim.ros import node_time


def burn(seconds: float) -> None:
    end = time.thread_time() + seconds
    while time.thread_time() < end:
        pass


@pytest.fixture
def counted(monkeypatch):
    """The module's counts from zero, sampled at once (no exact warm-up)."""
    monkeypatch.setattr(node_time, "_seconds", 0.0)
    monkeypatch.setattr(node_time, "_sampled_s", 0.0)
    monkeypatch.setattr(node_time, "WARM_UP_S", 0.0)


def spin(n: int) -> int:
    x = 0
    for _ in range(n):
        x += 1
    return x


def test_the_sampled_main_thread_counts_the_cpu_time_spent_inside_the_nodes_code(counted):
    # A third of the CPU time inside (the same loop, for n iterations inside and 2n outside), in
    # slices of about 0.1 ms, far shorter than a sample's period, and no clock read around them:
    # the estimate comes from where the samples fall.
    started = time.thread_time()
    spin(200_000)
    n = max(1, int(200_000 * 1e-4 / (time.thread_time() - started)))
    main = node_time.MAIN
    with node_time.sampling_main_thread() as sampled:
        assert sampled
        burn(0.01)                      # the first sample ends the (empty) warm-up
        assert not main.exact
        cpu, before = time.thread_time(), node_time.seconds()
        while time.thread_time() - cpu < 1.5:
            for _ in range(100):
                main.inside = True
                spin(n)
                main.inside = False
                spin(2 * n)
        cpu, counted_s = time.thread_time() - cpu, node_time.seconds() - before
    # 1.5 s of CPU time gives 375 samples at a 4 ms kernel tick: a standard error of about 7 %.
    assert counted_s == pytest.approx(cpu / 3, rel=0.3)
    # Afterwards: no timer, the handler as it was, exact counting again.
    assert signal.getsignal(signal.SIGPROF) == signal.SIG_DFL
    assert main.exact and not main.inside
    before = node_time.seconds()
    main.inside = True
    burn(0.05)                          # no sample comes any more
    main.inside = False
    assert node_time.seconds() == before


def test_a_short_run_is_counted_from_the_clock_until_the_warm_up_is_spent(counted, monkeypatch):
    monkeypatch.setattr(node_time, "WARM_UP_S", 60.0)
    with node_time.sampling_main_thread() as sampled:
        assert sampled
        node_time.MAIN.inside = True
        burn(0.1)
        node_time.MAIN.inside = False
        assert node_time.MAIN.exact and node_time.seconds() == 0.0   # the nodes' code reads the clock


def test_sampling_is_off_outside_the_main_thread_and_beside_another_profilers_handler(counted):
    results = []
    thread = threading.Thread(target=lambda: results.append(node_time.sampling_main_thread().__enter__()))
    thread.start()
    thread.join()
    assert results == [False]

    def profiler(signum, frame):
        pass
    previous = signal.signal(signal.SIGPROF, profiler)
    try:
        with node_time.sampling_main_thread() as sampled:
            assert not sampled and signal.getsignal(signal.SIGPROF) is profiler
    finally:
        signal.signal(signal.SIGPROF, previous)
