"""Repair a recording that was never closed (a run killed with SIGKILL, a power loss, a full
disk): ``composed-sim bag repair DIR``, and ``replay`` by itself.

Such a bag (outputs/recording/writer.py) has its MCAP file synced up to a complete record at its last flush,
but neither the MCAP summary and index nor metadata.yaml, which only ``close`` writes; its
custom_data is in ``UNFINISHED``. The repair reads the file's records in order with the mcap
library's stream reader, up to the first incomplete one (where the kill cut), keeps every
message of the complete ticks and writes them again with ``BagRecorder`` into a bag beside it,
whose files then take the old ones' places, metadata.yaml last: a complete rosbag2 directory
that rosbags, ``ros2 bag`` and ``replay --check`` read. A repair stopped half-way leaves a bag
that a second repair completes.

Tick k is complete once the /clock of tick k+1 is in the file: every message of tick k is
written before it, and a flush comes right after a /clock (``BagRecorder.flush``). A file whose
data section was finished (a DataEnd record: the writer was killed while writing the summary,
or metadata.yaml could not be written) holds its last tick whole.
"""
from __future__ import annotations

import json
import os
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

from composed_sim.outputs.recording import (CLOCK_TOPIC, CUSTOM_PREFIX, UNFINISHED, BagRecorder,
                                    RecordingError)

METADATA = "metadata.yaml"
_REPAIRING = ".repairing"       # the new bag, beside the old, until it takes its place


@dataclass
class Repaired:
    """What a repair recovered."""
    path: Path
    last_tick: int              # ticks 0 … last_tick are in the repaired bag
    messages: int               # messages kept, every topic
    topics: int
    dropped_messages: int       # written after the last complete tick
    dropped_bytes: int          # the incomplete record at the end of the file (cut by the kill)

    def __str__(self) -> str:
        dropped = []
        if self.dropped_messages:
            dropped.append(f"{self.dropped_messages} message{'s' if self.dropped_messages != 1 else ''} "
                           f"of the unfinished tick {self.last_tick + 1}")
        if self.dropped_bytes:
            dropped.append(f"{self.dropped_bytes} bytes of an incomplete record")
        ticks = f"ticks 0…{self.last_tick}" if self.last_tick else "tick 0"
        return (f"{self.path}: repaired: {ticks} recovered ({self.messages} messages on "
                f"{self.topics} topics)" + (f"; dropped {' and '.join(dropped)}" if dropped else ""))


def is_unfinished(path: Path) -> bool:
    """A bag directory whose writer never closed it: an MCAP file and no metadata.yaml."""
    return path.is_dir() and not (path / METADATA).exists() and any(path.glob("*.mcap"))


def repair(path: str | os.PathLike) -> Repaired:
    """Make the unfinished recording at ``path`` a complete bag of its complete ticks (module
    docstring). RecordingError, naming the directory, for anything else."""
    path = Path(path)
    if not path.is_dir():
        raise RecordingError(f"{path}: not a recording (not a directory)")
    if (path / METADATA).exists():
        raise RecordingError(f"{path}: a complete recording ({METADATA} is there): nothing to repair")
    files = sorted(path.glob("*.mcap"))
    if len(files) != 1:
        raise RecordingError(f"{path}: not a recording: {'no' if not files else len(files)} .mcap files in it")
    mcap_file = files[0]
    custom = _unfinished_custom_data(path)
    try:
        names = json.loads(custom.pop(CUSTOM_PREFIX + "robot_names"))
        tick_s = float(custom.pop(CUSTOM_PREFIX + "tick_s"))
    except (KeyError, ValueError) as e:
        raise RecordingError(f"{path / UNFINISHED}: no robot names or tick length ({e})") from None
    tick_ns = round(tick_s * 1e9)

    scan = _scan(mcap_file, tick_ns)
    last_tick = scan.last_clock_tick if scan.data_ended else scan.last_clock_tick - 1
    if last_tick < 0:
        raise RecordingError(f"{path}: nothing to recover: the run was stopped before its first tick was on disk")
    keep_until_ns = last_tick * tick_ns

    scratch = path / _REPAIRING
    shutil.rmtree(scratch, ignore_errors=True)      # a repair stopped half-way
    scratch.mkdir()
    new_bag = scratch / path.name
    kept = dropped = 0
    with BagRecorder(new_bag, robot_names=names, tick_s=tick_s) as bag:
        for key, value in custom.items():
            if key.startswith(CUSTOM_PREFIX):
                bag.set_custom(key[len(CUSTOM_PREFIX):], value)
        for topic, msgtype, stamp_ns, data in _messages(mcap_file, scan.end):
            if stamp_ns > keep_until_ns:
                dropped += 1
                continue
            bag.write_serialized(topic, msgtype, data, stamp_ns, always=True)
            kept += 1
        topics = sum(1 for count in bag.counts.values() if count)
    os.replace(new_bag / f"{path.name}.mcap", path / f"{path.name}.mcap")
    if mcap_file.name != f"{path.name}.mcap":       # the directory was renamed after the kill
        mcap_file.unlink()
    os.replace(new_bag / METADATA, path / METADATA)     # the bag is complete from here on
    (path / UNFINISHED).unlink(missing_ok=True)
    shutil.rmtree(scratch, ignore_errors=True)
    return Repaired(path, last_tick, kept, topics, dropped, scan.size - scan.end)


@dataclass
class _Scan:
    end: int                    # bytes up to the end of the last complete record
    size: int                   # bytes in the file
    last_clock_tick: int        # -1: no /clock
    data_ended: bool            # the writer finished the data section


def _scan(mcap_file: Path, tick_ns: int) -> _Scan:
    """Where the file's complete records end, and the last /clock in them."""
    from mcap.records import Channel, DataEnd, Message

    clock_channels: set[int] = set()
    last_clock_ns, data_ended, end = -1, False, 0
    for record, offset in _records(mcap_file):
        end = offset
        if isinstance(record, Channel) and record.topic == CLOCK_TOPIC:
            clock_channels.add(record.id)
        elif isinstance(record, Message) and record.channel_id in clock_channels:
            last_clock_ns = max(last_clock_ns, record.log_time)
        elif isinstance(record, DataEnd):
            data_ended = True
    last = round(last_clock_ns / tick_ns) if last_clock_ns >= 0 else -1
    return _Scan(end, mcap_file.stat().st_size, last, data_ended)


def _messages(mcap_file: Path, end: int) -> Iterator[tuple[str, str, int, bytes]]:
    """(topic, message type, log time in ns, CDR bytes) of each message in the first ``end`` bytes."""
    from mcap.records import Channel, Message, Schema

    schemas: dict[int, str] = {}
    channels: dict[int, tuple[str, str]] = {}
    for record, offset in _records(mcap_file):
        if offset > end:
            return
        if isinstance(record, Schema):
            schemas[record.id] = record.name
        elif isinstance(record, Channel):
            channels[record.id] = (record.topic, schemas[record.schema_id])
        elif isinstance(record, Message):
            topic, msgtype = channels[record.channel_id]
            yield topic, msgtype, record.log_time, record.data


def _records(mcap_file: Path) -> Iterator[tuple[object, int]]:
    """Each complete record of the file (those inside a chunk too), with the offset where the
    record holding it ends; stops at the first incomplete or damaged record."""
    from mcap.exceptions import InvalidMagic, McapError
    from mcap.stream_reader import StreamReader

    with open(mcap_file, "rb") as f:
        reader = StreamReader(f).records
        while True:
            try:
                record = next(reader)
            except StopIteration:
                return
            except InvalidMagic:
                raise RecordingError(f"{mcap_file}: not an MCAP file") from None
            except (McapError, ValueError):     # EndOfFile: where the kill cut; else damage
                return
            yield record, f.tell()


def _unfinished_custom_data(path: Path) -> dict[str, str]:
    import yaml
    try:
        data = yaml.safe_load((path / UNFINISHED).read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise RecordingError(f"{path}: not a composed-sim recording that can be repaired (no {UNFINISHED} "
                             f"beside its MCAP file)") from None
    except (OSError, yaml.YAMLError) as e:
        raise RecordingError(f"{path / UNFINISHED}: unreadable ({e})") from None
    if not isinstance(data, dict):
        raise RecordingError(f"{path / UNFINISHED}: not a mapping of custom_data")
    return {str(k): str(v) for k, v in data.items()}
