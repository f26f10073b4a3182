"""Fast DDS's shared-memory files of dead processes are removed (hosting/dds/shared_memory.py): by
Fast DDS's own lock rule and the processes' maps, never a live process's; a run killed outright
leaves nothing in /dev/shm after the next run, and a run that ends leaves nothing of its own.
Other test processes share this machine's /dev/shm: the end-to-end test looks only at the files
its own runs used."""
import fcntl
import json
import mmap
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import psutil
import pytest

from composed_sim.hosting.dds.shared_memory import (CREATING_S, SHM_PREFIXES, remove_own_shared_memory,
                                               remove_stale_shared_memory)

ROOT = Path(__file__).resolve().parents[2]
FLOCKING = ROOT / "worlds" / "flocking.yaml"
SHM = Path("/dev/shm")


@pytest.fixture
def shm_dir(tmp_path):
    """A folder of its own in /dev/shm: the same file system (tmpfs) as Fast DDS's files."""
    import shutil
    import tempfile
    folder = Path(tempfile.mkdtemp(prefix="composed_sim_test_", dir=SHM))
    yield folder
    shutil.rmtree(folder, ignore_errors=True)


def _make(folder: Path, *names: str, size: int = 100, age_s: float = 0.0) -> None:
    for name in names:
        (folder / name).write_bytes(b"x" * (0 if name.endswith(("_el", "_sl")) else size))
        if age_s:
            then = time.time() - age_s
            os.utime(folder / name, (then, then))


def _lock(path: Path, how=fcntl.LOCK_EX) -> int:
    fd = os.open(path, os.O_RDONLY)
    fcntl.flock(fd, how | fcntl.LOCK_NB)
    return fd


def test_dead_files_go_whatever_their_age_and_live_ones_stay(shm_dir):
    _make(shm_dir, "fastrtps_0123456789abcdef", "fastrtps_0123456789abcdef_el",      # dead participant
          "fastrtps_fedcba9876543210", "fastrtps_fedcba9876543210_el",                # live participant
          "fastrtps_port7411", "fastrtps_port7411_el", "sem.fastrtps_port7411_mutex",  # dead reader
          "fastrtps_port7413", "fastrtps_port7413_sl", "sem.fastrtps_port7413_mutex",  # live shared readers
          "fastrtps_port7415", "sem.fastrtps_port7417_mutex")                          # a writer's; a lone mutex
    _make(shm_dir, "fastrtps_port7419", "fastrtps_port7421", age_s=2 * CREATING_S)   # no lock: one mapped
    _make(shm_dir, "fastrtps_00000000000000aa", age_s=2 * CREATING_S)    # its lock file gone, nobody maps it
    _make(shm_dir, "fastdds_port7423", "fastdds_port7423_el", "unrelated_el")
    held = [_lock(shm_dir / "fastrtps_fedcba9876543210_el"), _lock(shm_dir / "fastrtps_port7413_sl", fcntl.LOCK_SH)]
    with open(shm_dir / "fastrtps_port7421", "r+b") as f, mmap.mmap(f.fileno(), 100):    # a live writer maps it
        try:
            assert remove_stale_shared_memory(shm_dir) == 10
        finally:
            for fd in held:
                os.close(fd)
    assert sorted(p.name for p in shm_dir.iterdir()) == sorted([
        "fastrtps_fedcba9876543210", "fastrtps_fedcba9876543210_el",
        "fastrtps_port7413", "fastrtps_port7413_sl", "sem.fastrtps_port7413_mutex",
        "fastrtps_port7415",              # without a lock file: changed less than CREATING_S ago
        "fastrtps_port7421", "unrelated_el"])


def test_an_empty_port_file_left_by_a_killed_creator_is_removed(shm_dir):
    """A port file of size zero hangs every participant that opens it: it has no lock and nobody
    maps it, so it goes once it is older than a moment; a fresh one (being sized) stays."""
    _make(shm_dir, "fastrtps_port7411", "sem.fastrtps_port7411_mutex", size=0, age_s=2 * CREATING_S)
    _make(shm_dir, "fastrtps_port7413", "sem.fastrtps_port7413_mutex", size=0)
    assert remove_stale_shared_memory(shm_dir) == 2
    assert sorted(p.name for p in shm_dir.iterdir()) == ["fastrtps_port7413", "sem.fastrtps_port7413_mutex"]


def test_a_process_removes_its_own_files_and_leaves_the_others(shm_dir):
    _make(shm_dir, "fastrtps_0123456789abcdef", "fastrtps_0123456789abcdef_el",
          "fastrtps_port7411", "fastrtps_port7411_el", "sem.fastrtps_port7411_mutex",
          "fastrtps_port7413", "fastrtps_port7413_sl",                      # shared with another process
          "fastrtps_fedcba9876543210", "fastrtps_fedcba9876543210_el")     # another process's
    mine = [_lock(shm_dir / "fastrtps_0123456789abcdef_el"), _lock(shm_dir / "fastrtps_port7411_el"),
            _lock(shm_dir / "fastrtps_port7413_sl", fcntl.LOCK_SH)]
    other = subprocess.Popen([sys.executable, "-c", (
        "import fcntl, os, sys\n"
        "a = os.open(sys.argv[1], os.O_RDONLY); fcntl.flock(a, fcntl.LOCK_EX)\n"
        "b = os.open(sys.argv[2], os.O_RDONLY); fcntl.flock(b, fcntl.LOCK_SH)\n"
        "print('held', flush=True); sys.stdin.read()"),
        str(shm_dir / "fastrtps_fedcba9876543210_el"), str(shm_dir / "fastrtps_port7413_sl")],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        assert other.stdout.readline() == "held\n"
        assert remove_own_shared_memory(shm_dir) == 5
    finally:
        other.kill()
        other.wait()
        for fd in mine:
            os.close(fd)
    assert sorted(p.name for p in shm_dir.iterdir()) == [
        "fastrtps_fedcba9876543210", "fastrtps_fedcba9876543210_el", "fastrtps_port7413", "fastrtps_port7413_sl"]


def _files_of(pids: set[int]) -> set[tuple[str, int]]:
    """(name, inode) of Fast DDS's /dev/shm files that the processes ``pids`` map or hold a lock on.
    Not the others: LTTng's ``lttng-ust-wait-*`` (the tracing library loaded with rclpy maps them in every
    process, and they stay, whoever made them), which made this test fail whenever no other
    process on the machine happened to map them when it looked."""
    inodes = set()
    for pid in pids:
        try:
            inodes |= {int(line.split()[4]) for line in Path(f"/proc/{pid}/maps").read_text().splitlines()
                       if " /dev/shm/" in line}
        except OSError:
            pass
    for line in Path("/proc/locks").read_text().splitlines():
        fields = line.split()
        if fields[1] != "->" and int(fields[4]) in pids:
            inodes.add(int(fields[5].split(":")[2]))
    return {(p.name, p.stat().st_ino) for p in SHM.iterdir()
            if p.name.removeprefix("sem.").startswith(SHM_PREFIXES) and _ino(p) in inodes}


def _ino(path: Path):
    try:
        return path.stat().st_ino
    except OSError:
        return None


def _in_use() -> set[int]:
    """Inodes of /dev/shm files that some live process maps or locks now."""
    return {ino for _, ino in _files_of({int(p) for p in os.listdir("/proc") if p.isdigit()})}


def _run_until(tmp_path: Path, name: str, ticks: int, *extra: str) -> tuple[subprocess.Popen, set, list]:
    """A recording run with 2 workers, once past its checkpoint at tick 100: the process, the
    /dev/shm files its processes use then, and those processes."""
    out = tmp_path / name
    log = open(tmp_path / f"{name}.log", "wb")
    proc = subprocess.Popen([sys.executable, "-m", "composed_sim.cli", "run", str(FLOCKING), "--robots", "20",
                             "--ticks", str(ticks), "--workers", "2", "--out", str(out), "--record",
                             str(tmp_path / f"{name}.bag"), "--no-progress", "--no-picture", *extra],
                            cwd=ROOT, stdout=subprocess.DEVNULL, stderr=log, start_new_session=True)
    deadline = time.monotonic() + 120
    while not (out / "summary.json").exists() or json.loads((out / "summary.json").read_text())["ticks"] < 100:
        if proc.poll() is not None or time.monotonic() > deadline:
            os.killpg(proc.pid, signal.SIGKILL)
            pytest.fail((tmp_path / f"{name}.log").read_text())
        time.sleep(0.1)
    processes = [psutil.Process(proc.pid), *psutil.Process(proc.pid).children(recursive=True)]
    used = _files_of({p.pid for p in processes})
    assert used, "the run uses no shared memory"
    return proc, used, processes


# Both runs in a domain of their own: a killed run's domain is free again at once, and another
# test's run in a parallel test run would take it (the first free from 0 up) and with it the
# domain's port files.
OWN_DOMAIN = ("--domain-id", "87")


def _of_domain(name: str, domain: int) -> bool:
    """A participant's segment, or a port of ``domain``'s range (7400 + 250 d, 250 ports): files no
    process outside the domain opens. Fast DDS's shared-memory ports below 7400 (7000, 7001, ...)
    belong to no domain: any participant on the machine takes the first whose lock is free, a dead
    run's file as it is, so another test's run may take one of these runs' files and be killed
    with it (a run of the default suite, 2026-12-07: fastrtps_port7001_el left by nobody)."""
    stem = name.removeprefix("sem.").removesuffix("_mutex").removesuffix("_el").removesuffix("_sl")
    port = stem.split("_", 1)[1].removeprefix("port")
    if not port.isdigit():
        return True
    return 7400 + 250 * domain <= int(port) < 7400 + 250 * (domain + 1)


def _holders(files: set[tuple[str, int]]) -> str:
    """Which live processes map or lock each of ``files``: for a failure's message."""
    out = []
    for name, ino in sorted(files):
        pids = [pid for pid in (int(p) for p in os.listdir("/proc") if p.isdigit()) if (name, ino) in _files_of({pid})]
        out.append(f"{name}: " + (", ".join(f"{pid} {_cmdline(pid)}" for pid in pids) or "nobody"))
    return "\n".join(out)


def _cmdline(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()[:120]
    except OSError:
        return "?"


def test_a_killed_run_leaves_nothing_after_the_next_and_the_next_nothing_of_its_own(tmp_path):
    killed, killed_files, processes = _run_until(tmp_path, "killed", 100_000, *OWN_DOMAIN)
    killed.kill()                 # SIGKILL: no clean-up runs; the death signal takes the workers
    killed.wait()
    _, alive = psutil.wait_procs(processes[1:], timeout=10)
    assert not [p for p in alive if p.status() != psutil.STATUS_ZOMBIE]
    left = {(n, i) for n, i in killed_files if _ino(SHM / n) == i}
    assert left, "a killed run leaves its files (else this test shows nothing)"
    after, after_files, _ = _run_until(tmp_path, "after", 150, *OWN_DOMAIN)
    assert after.wait(timeout=300) == 0, (tmp_path / "after.log").read_text()
    err = (tmp_path / "after.log").read_text()
    swept = "shared-memory file" in err and "of dead processes from /dev/shm" in err
    # In a parallel test run another test's run may start first and sweep them itself (every run
    # sweeps the files of dead processes): then they are gone before this one looks.
    still = {(n, i) for n, i in left if _ino(SHM / n) == i}
    assert swept or not still, f"{err}\nleft, with their holders:\n{_holders(still)}"
    in_use = _in_use()            # by other processes on this machine: not only the runs'
    remaining = sorted(n for n, i in killed_files | after_files
                       if _ino(SHM / n) == i and i not in in_use and _of_domain(n, int(OWN_DOMAIN[1])))
    assert remaining == [], _holders({(n, i) for n, i in killed_files | after_files if n in remaining})
