"""Fast DDS's shared-memory files in /dev/shm whose owner processes are gone: removed by each
`composed-sim run` first, and a run that ends with its fast exit removes its own.

Fast DDS gives each participant a shared-memory segment in /dev/shm (``fastrtps_<id>``, about
0.5 MB) and each port it listens on one (``fastrtps_port<N>``, with its named mutex
``sem.fastrtps_port<N>_mutex``). Who owns them is told by lock files next to them, which their
owners hold with flock while they live and which Fast DDS itself tests to tell a dead owner:
``fastrtps_<id>_el`` (the participant, exclusive), ``fastrtps_port<N>_el`` (the port's one
reader, exclusive) or ``_sl`` (its readers, shared). A process that ends without destroying its
participants (a run that ends with os._exit, a worker or controller killed, a SIGKILL) leaves
them behind: RAM on a tmpfs, and error lines from later participants that trip over the dead
ports. Worse is a port file of size zero: its creator died between creating the file and sizing
it; boost's open-or-create then waits for it forever inside rcl's participant creation.

The rule (docs/faults.md, "Shared memory"): a participant's segment is dead when its lock can be
taken (Fast DDS's own test; taken, the file is removed while held, and a creator that locks the
name later finds it gone and picks another), or when its lock file is gone (its owner takes the
lock before it makes the segment and removes the segment before the lock; Fast DDS's own test
removes a free lock file) and nobody maps it. A port is dead when none of its lock files is held
and no live process maps it (every /proc/<pid>/maps); its mutex, when its port is gone and no
process maps it (a process maps it only while it holds it). A port without any lock file is
left for CREATING_S after its last change (the moment between its creation and its creator's
mapping it). Where a process that holds a lock here has maps that cannot be read (another
user's), such a port and the mutexes are left for STALE_AFTER_S: their users cannot be known.
"""
from __future__ import annotations

import contextlib
import os
from pathlib import Path

SHM_DIR = Path("/dev/shm")
SHM_PREFIXES = ("fastrtps_", "fastdds_")
CREATING_S = 5.0
STALE_AFTER_S = 60.0


def remove_stale_shared_memory(directory: Path = SHM_DIR) -> int:
    """Remove Fast DDS's shared-memory files in ``directory`` whose owner processes are gone (the
    rule above); how many files went. Files of live processes are never touched."""
    import time
    try:
        names = sorted(os.listdir(directory))
    except OSError:
        return 0
    directory = Path(directory)
    mapped, complete = _mapped_inodes(directory=directory)
    settled = time.time() - (CREATING_S if complete else STALE_AFTER_S)   # changed before: not being made
    removed = 0
    ports: dict[str, list[str]] = {}
    for name in names:
        if not name.startswith(SHM_PREFIXES):
            continue
        stem = name[:-len("_el")] if name.endswith(("_el", "_sl")) else name
        if _is_port(stem):
            ports.setdefault(stem, []).append(name)
        elif name.endswith("_el"):          # a participant's lock: its segment goes with it
            removed += _remove_if_free(directory / name, [directory / stem])
        elif f"{name}_el" not in names and _unused(directory / name, mapped, False, settled):
            removed += _unlink(directory / name)     # a segment whose lock is gone
    for port, files in ports.items():
        removed += _remove_if_dead_port(directory, port, files, mapped, settled)
    for name in names:                      # the mutexes of ports that are gone
        if name.startswith("sem.") and name.endswith("_mutex") and name[len("sem."):].startswith(SHM_PREFIXES):
            path = directory / name
            if not (directory / name[len("sem."):-len("_mutex")]).exists() and _unused(path, mapped, complete, settled):
                removed += _unlink(path)
    return removed


def remove_own_shared_memory(directory: Path = SHM_DIR) -> int:
    """Before this process ends without destroying its participants (``os._exit``): remove the
    segments of its participants and of the ports that only it reads (their lock files held by
    this process alone, /proc/locks), with the mutexes of those ports that no other process maps;
    how many files went. What others still use stays; they keep their mappings either way."""
    holders = _lock_holders()
    mapped, _ = _mapped_inodes(but=os.getpid(), directory=directory)
    directory, removed = Path(directory), 0
    try:
        names = os.listdir(directory)
    except OSError:
        return 0
    for name in names:
        if not (name.startswith(SHM_PREFIXES) and name.endswith(("_el", "_sl"))):
            continue
        lock = directory / name
        if holders.get(_file_key(lock)) != {os.getpid()}:
            continue
        stem = name[:-len("_el")]
        removed += _unlink(directory / stem) + _unlink(lock)
        mutex = directory / f"sem.{stem}_mutex"
        if _is_port(stem) and not _mapped(mutex, mapped):
            removed += _unlink(mutex)
    return removed


def _lock_holders() -> dict:
    """(device, inode) → the pids holding a lock on it (/proc/locks; waiters left out)."""
    holders: dict = {}
    try:
        with open("/proc/locks") as f:
            lines = f.read().splitlines()
    except OSError:
        return holders
    for line in lines:
        fields = line.split()
        if len(fields) < 6 or fields[1] == "->":
            continue
        major, minor, inode = fields[5].split(":")
        holders.setdefault((f"{int(major, 16):02x}:{int(minor, 16):02x}".encode(), int(inode)), set()).add(int(fields[4]))
    return holders


def _file_key(path: Path):
    """(device as /proc writes it, inode) of ``path``, or None."""
    try:
        status = os.stat(path)
    except OSError:
        return None
    return f"{os.major(status.st_dev):02x}:{os.minor(status.st_dev):02x}".encode(), status.st_ino


def _is_port(stem: str) -> bool:
    """``fastrtps_port<N>``: a port's segment (else a participant's)."""
    rest = stem.split("_", 1)[1]
    return rest.startswith("port") and rest[len("port"):].isdigit()


def _remove_if_dead_port(directory: Path, port: str, files: list[str], mapped: set, settled: float) -> int:
    """A port's segment and lock files, when no lock is held and no live process maps it."""
    segment = directory / port
    locks = [directory / f for f in files if f != port]
    with contextlib.ExitStack() as held:
        for lock in locks:
            if not held.enter_context(_taken(lock)):
                return 0                    # a live reader holds it
        if port in files and (_mapped(segment, mapped) or (not locks and not _settled(segment, settled))):
            return 0
        # Under the locks taken: a reader that comes now finds its lock gone and makes it anew.
        return sum(_unlink(p) for p in [segment, *locks])


def _remove_if_free(lock: Path, owned: list[Path]) -> int:
    """``lock`` and the files it guards, when no process holds ``lock``."""
    with _taken(lock) as taken:
        return sum(_unlink(p) for p in [*owned, lock]) if taken else 0


@contextlib.contextmanager
def _taken(lock: Path):
    """Take ``lock`` (flock, exclusive, without waiting) for the block: True when taken, False
    when a live process holds it (or it is gone or unreadable). As Fast DDS does, a lock taken on
    a file that was removed and made again meanwhile does not count."""
    import fcntl
    try:
        fd = os.open(lock, os.O_RDONLY)
    except OSError:
        yield False
        return
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        taken = os.stat(lock).st_ino == os.fstat(fd).st_ino
    except OSError:
        taken = False
    try:
        yield taken
    finally:
        os.close(fd)


def _mapped_inodes(but: int = 0, directory: Path = SHM_DIR) -> tuple[set, bool]:
    """(device, inode) of the files in ``directory`` that live processes (all but ``but``) map, and
    whether that is all of them: true unless a process whose maps cannot be read (another
    user's, or one hidden from this one) holds a lock on a file in ``directory`` (every process
    using Fast DDS's shared memory holds at least its participant's)."""
    found, unreadable = set(), set()
    inside = f" {os.path.realpath(directory)}/".encode()
    for pid in os.listdir("/proc"):
        if not pid.isdigit() or int(pid) == but:
            continue
        try:
            with open(f"/proc/{pid}/maps", "rb") as f:
                maps = f.read()
        except PermissionError:
            unreadable.add(int(pid))
            continue
        except OSError:                     # ended meanwhile
            continue
        for line in maps.splitlines():
            if inside in line:
                fields = line.split(maxsplit=5)
                found.add((fields[3], int(fields[4])))
    if not unreadable:
        return found, True
    device = (_file_key(directory) or (None,))[0]
    lockers = {pid for (dev, _), pids in _lock_holders().items() if dev == device for pid in pids}
    return found, not (lockers & unreadable)


def _mapped(path: Path, mapped: set) -> bool:
    return _file_key(path) in mapped


def _settled(path: Path, settled: float) -> bool:
    try:
        return os.stat(path).st_mtime < settled
    except OSError:
        return False


def _unused(path: Path, mapped: set, complete: bool, settled: float) -> bool:
    """A mutex is mapped from the moment it exists (sem_open makes it aside and links it in
    ready) until its users close it: where every process's maps were read, not mapped is unused."""
    return not _mapped(path, mapped) and (complete or _settled(path, settled))


def _unlink(path: Path) -> int:
    try:
        path.unlink()
        return 1
    except OSError:
        return 0                # gone meanwhile, or another user's
