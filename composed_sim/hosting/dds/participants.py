"""Several DDS participants in one process that ignore one another.

Fast DDS matches each new endpoint against every local endpoint of the other kind, copying each
one's discovery data first (EDP ``pairing_*_with_any_local_*``), so creating E endpoints in one
participant costs O(E²) (a minute at 1280 robots: docs/speed.md). Participants that discover
one another do the same work for each other's endpoints, so splitting the endpoints over
participants does not help by itself. With Fast DDS's ``ignoreParticipantFlags =
FILTER_SAME_PROCESS`` the participants of this process skip one another's discovery traffic: a
composed host split into self-contained participant groups (a simulator node and its robots' controllers per
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
    gave Fast DDS a profile file of their own (it is respected; the groups then discover one another,
    which costs set-up time, not correctness). True when our profile is the one named.

    Effective only if called before the process's first participant (Fast DDS loads the profile
    once); a group's topics never overlap another's, so an earlier participant changes nothing
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
