"""Several DDS participants in one process that ignore one another.

Fast DDS matches each new endpoint against every local endpoint of the other kind, copying each
one's discovery data first (EDP ``pairing_*_with_any_local_*``), so creating E endpoints in one
participant costs O(E²) (a minute at 1280 robots: docs/speed.md). Participants that discover
one another do the same work for each other's endpoints, so splitting the endpoints over
participants does not help by itself. With Fast DDS's ``ignoreParticipantFlags =
FILTER_SAME_PROCESS`` the participants of this process skip one another's discovery traffic: a
composed host split into self-contained shards (a simulator node and its robots' controllers per
participant) pays O(E²/K). Other processes still discover every participant, so ``ros2 topic
echo /bot7/light`` or a recorder elsewhere sees every topic as before.

The same profile (data/fastdds_participants.xml) starts every DataWriter's and DataReader's
history with room for one sample instead of Fast DDS's 100, grown when needed: those unused
samples were close to half of a robot's endpoints' memory (docs/speed.md), and trajectories and
ticks are the same without them.

Fast DDS reads its default profile when the process creates its first participant, from the file
named by ``FASTRTPS_DEFAULT_PROFILES_FILE``.
"""
from __future__ import annotations

import os
from pathlib import Path

PROFILE = Path(__file__).resolve().parents[2] / "data" / "fastdds_participants.xml"
PROFILE_VARIABLES = ("FASTRTPS_DEFAULT_PROFILES_FILE", "FASTDDS_DEFAULT_PROFILES_FILE")


def ignore_participants_of_this_process() -> bool:
    """Make the participants this process creates from now on ignore one another, unless the user
    gave Fast DDS a profile file of their own (it is respected; shards then discover one another,
    which costs set-up time, not correctness). True when our profile is the one named.

    Effective only if called before the process's first participant (Fast DDS loads the profile
    once); a shard's topics never overlap another's, so an earlier participant changes nothing
    but the set-up time."""
    given = [os.environ[v] for v in PROFILE_VARIABLES if os.environ.get(v)]
    if not given:
        os.environ[PROFILE_VARIABLES[0]] = str(PROFILE)
        return True
    return all(Path(g).resolve() == PROFILE for g in given)


# --- the participants of a run's worker processes ----------------------------------------------
#
# Fast DDS's FILTER_SAME_PROCESS compares the first 8 bytes of two participants' GUID prefixes
# (vendor, host, process). A participant's whole prefix can be set in its profile: the worker
# host gives every worker's one participant a prefix whose first 8 bytes are the run's, and whose
# last 4 are the worker's number. The workers then skip one another's discovery as the
# participants of one process do (their topics never overlap), and any other process, whose
# prefix differs, discovers every worker. Without this, every endpoint of one worker would be
# matched against every endpoint of the others: set-up O(E²) again. The worker's profile is ours
# (data/fastdds_participants.xml) with the prefix added.


def _with_prefix(profile: str, prefix: str) -> str:
    """Our profile, its participant's GUID prefix set (``01.0f.….``)."""
    participant = '<participant profile_name="composed_sim_participant" is_default_profile="true">\n    <rtps>'
    if participant not in profile:
        raise ValueError(f"{PROFILE} has no participant profile to give a prefix")
    return profile.replace(participant, f"{participant}\n      <prefix>{prefix}</prefix>")


def run_prefix() -> bytes:
    """The first 8 bytes of a run's worker participants' GUID prefixes: Fast DDS's vendor id
    (1.15), this host's id as Fast DDS computes it, and 4 random bytes for the run."""
    return bytes([1, 15]) + _fast_dds_host_id() + os.urandom(4)


def use_worker_prefix(prefix: bytes, directory: Path) -> bool:
    """Before the process's first participant: its participant gets the GUID prefix ``prefix``
    (12 bytes) and ignores the participants whose prefix starts like its own. False (and nothing
    changes) when the user named a Fast DDS profile file of their own."""
    if len(prefix) != 12:
        raise ValueError(f"a GUID prefix has 12 bytes, got {len(prefix)}")
    given = [os.environ[v] for v in PROFILE_VARIABLES if os.environ.get(v)]
    if any(Path(g).resolve() != PROFILE for g in given):       # the user's own profile: respected
        return False
    for v in PROFILE_VARIABLES:
        os.environ.pop(v, None)
    path = Path(directory) / f"fastdds_worker_{prefix.hex()}.xml"
    path.write_text(_with_prefix(PROFILE.read_text(), ".".join(f"{b:02x}" for b in prefix)))
    os.environ[PROFILE_VARIABLES[0]] = str(path)
    return True


def _fast_dds_host_id() -> bytes:
    """Fast DDS's host id (utils/Host.hpp): the MD5 of this host's IPv4 addresses (16-byte locator
    addresses), folded into 16 bits; 127.1 when there is none. Participants compare it to tell
    another host's; a wrong value would only make ours look foreign to FILTER_DIFFERENT_HOST."""
    import hashlib
    import socket

    import psutil
    addresses = [a.address for nic in psutil.net_if_addrs().values() for a in nic
                 if a.family == socket.AF_INET and not a.address.startswith("127.")]
    if not addresses:
        return bytes([127, 1])
    digest = hashlib.md5(b"".join(bytes(12) + socket.inet_aton(a) for a in addresses)).digest()
    value = 0
    for i in range(0, 16, 2):
        value ^= (digest[i] << 8) | digest[i + 1]
    return bytes([value & 0xFF, value >> 8])


# --- shared memory left behind by dead processes --------------------------------------------------
#
# Fast DDS gives each participant a shared-memory segment in /dev/shm (``fastrtps_<id>``, about
# 0.5 MB) and each port one (``fastrtps_port<N>``), each with a ``_el`` file that its owner keeps
# locked (flock) while it lives. A process that ends without destroying its participants (a run
# that ends with os._exit, a worker or controller killed) leaves them behind: RAM on a tmpfs, and
# error lines from later participants that trip over the dead ports. A run removes them first.
#
# Worse is a port file of size zero: its creator died between creating the file and sizing it
# (killed during start-up). boost's open-or-create then waits for the segment to be initialised,
# forever, inside rcl's participant creation, where Python's SIGTERM handler never runs: every
# later participant whose port number falls on it hangs (measured: a node on a domain whose user
# port has such a file never comes up; multi-process start-ups of 160 robots stalled on them). No
# port of a live process stays empty for more than a moment, so an old empty one goes too.

SHM_DIR = Path("/dev/shm")
STALE_AFTER_S = 60.0     # younger files may belong to a participant being created right now
EMPTY_PORT_AFTER_S = 10.0  # a port file is sized right after it is created


def remove_stale_shared_memory(directory: Path = SHM_DIR, *, stale_after_s: float = STALE_AFTER_S) -> int:
    """Remove Fast DDS's shared-memory files whose owner is dead (their ``_el`` lock is free and
    older than ``stale_after_s``) and port files left empty (older than ``EMPTY_PORT_AFTER_S``);
    how many segments went. Files of live processes are never touched: their lock is held."""
    import fcntl
    import time
    now = time.time()
    try:
        locks = list(Path(directory).glob("fastrtps_*_el"))
        ports = list(Path(directory).glob("fastrtps_port*[0-9]"))
    except OSError:
        return 0
    removed = 0
    for lock in locks:
        try:
            if now - lock.stat().st_mtime < stale_after_s:
                continue
            fd = os.open(lock, os.O_RDWR)
        except OSError:
            continue            # gone meanwhile, or another user's
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            os.close(fd)        # held: its owner lives
            continue
        try:
            segment = Path(str(lock)[:-len("_el")])
            segment.unlink(missing_ok=True)
            _port_mutex(segment).unlink(missing_ok=True)
            lock.unlink(missing_ok=True)
            removed += 1
        except OSError:
            pass
        finally:
            os.close(fd)
    for port in ports:
        try:
            status = port.stat()
            if status.st_size == 0 and now - status.st_mtime >= EMPTY_PORT_AFTER_S:
                port.unlink()
                _port_mutex(port).unlink(missing_ok=True)
                removed += 1
        except OSError:
            pass                # gone meanwhile, or another user's
    return removed


def _port_mutex(segment: Path) -> Path:
    """A port's named mutex (``sem.fastrtps_port<N>_mutex``): a process killed while holding it
    leaves it locked, and the next owner of that port number would wait for it forever. A
    participant's own segment has none (the path names no file)."""
    return segment.parent / f"sem.{segment.name}_mutex"
