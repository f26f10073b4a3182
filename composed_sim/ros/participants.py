"""Several DDS participants in one process that ignore one another.

Fast DDS matches each new endpoint against every local endpoint of the other kind, copying each
one's discovery data first (EDP ``pairing_*_with_any_local_*``), so creating E endpoints in one
participant costs O(E²): 70 s for the 11,500 endpoints of 1280 robots. Participants that discover
one another do the same work for each other's endpoints, so splitting the endpoints over
participants does not help by itself. With Fast DDS's ``ignoreParticipantFlags =
FILTER_SAME_PROCESS`` the participants of this process skip one another's discovery traffic: a
composed host split into self-contained shards (a simulator node and its robots' controllers per
participant) pays O(E²/K). Other processes still discover every participant, so ``ros2 topic
echo /bot7/light`` or a recorder elsewhere sees every topic as before.

Fast DDS reads its default profile when the process creates its first participant, from the file
named by ``FASTRTPS_DEFAULT_PROFILES_FILE``.
"""
from __future__ import annotations

import os
from pathlib import Path

PROFILE = Path(__file__).resolve().parent.parent / "data" / "fastdds_participants.xml"
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
