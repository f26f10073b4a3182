"""Reading a recording back: the swarm state of every tick, and what the recorder stored beside it
(the robots' names, the tick, the world, the executor)."""
from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Optional

import numpy as np

from composed_sim.outputs.recording.messages import (CUSTOM_PREFIX, NS_PER_S, STATE_DTYPE, SWARM_STATE_TOPIC,
                                                     UNFINISHED, RecordingError, new_typestore, unpack_rgb)

if TYPE_CHECKING:
    from composed_sim.world.schema import World


@dataclass
class Recording:
    """A recording's swarm state, Trajectories-like (``positions``, ``headings``, ``names``)."""
    names: list[str]
    tick_s: float
    stamps_ns: np.ndarray       # [T] sim time of each swarm state
    positions: np.ndarray       # [T, n, 2] m
    headings: np.ndarray        # [T, n] rad
    led_colors: np.ndarray      # [T, n, 3] uint8 display colours (0 = no LED lit)
    world: Optional["World"]    # the world stored at record time, if any
    topics: dict[str, tuple[str, int]]    # topic -> (message type, message count)
    executor: Optional[str] = None        # the executor that ran the recorded run, if stored

    @property
    def ticks(self) -> np.ndarray:
        """[T] tick number of each swarm state."""
        return np.rint(self.stamps_ns / (self.tick_s * NS_PER_S)).astype(int)

    @property
    def ticks_done(self) -> int:
        """The last recorded tick (0 for an empty bag)."""
        return int(self.ticks[-1]) if len(self.stamps_ns) else 0


def read_recording(path: str | os.PathLike) -> Recording:
    """Read a bag written by ``BagRecorder``: the swarm state of every tick and what it stored."""
    from rosbags.rosbag2 import Reader

    path = Path(path)
    custom = _custom_data(path)
    typestore = new_typestore()
    try:
        with Reader(path) as reader:
            topics = {name: (info.msgtype, info.msgcount) for name, info in reader.topics.items()}
            conns = [c for c in reader.connections if c.topic == SWARM_STATE_TOPIC]
            stamps, clouds = [], []
            for conn, ns, raw in reader.messages(connections=conns):
                msg = typestore.deserialize_cdr(raw, conn.msgtype)
                stamps.append(ns)
                clouds.append(_decode_state(msg, path, ns))
    except RecordingError:
        raise
    except Exception as e:    # noqa: BLE001 - rosbags' reader errors and file-system errors alike
        raise RecordingError(f"{path}: not a readable rosbag2 recording: {e}") from None
    names = json.loads(custom[CUSTOM_PREFIX + "robot_names"]) if CUSTOM_PREFIX + "robot_names" in custom else \
        [f"robot{i}" for i in range(len(clouds[0]) if clouds else 0)]
    n = len(names)
    if any(len(c) != n for c in clouds):
        raise RecordingError(f"{path}: a swarm state does not hold the {n} recorded robots")
    tick_s = float(custom.get(CUSTOM_PREFIX + "tick_s", "nan"))
    if not math.isfinite(tick_s):
        tick_s = (stamps[1] - stamps[0]) / NS_PER_S if len(stamps) > 1 else 0.1
    order = np.argsort(stamps, kind="stable")
    pts = np.stack([clouds[i] for i in order]) if clouds else np.zeros((0, n), STATE_DTYPE)
    world = None
    if CUSTOM_PREFIX + "world" in custom:
        import yaml
        from composed_sim.world.loader import world_from_dict
        world = world_from_dict(yaml.safe_load(custom[CUSTOM_PREFIX + "world"]),
                                source=f"{path}/metadata.yaml custom_data {CUSTOM_PREFIX}world")
    return Recording(names=names, tick_s=tick_s,
                     stamps_ns=np.asarray(stamps, dtype=np.int64)[order],
                     positions=np.stack([pts["x"], pts["y"]], axis=-1),
                     headings=pts["yaw"].copy(), led_colors=unpack_rgb(pts["rgb"]),
                     world=world, topics=topics, executor=custom.get(CUSTOM_PREFIX + "executor"))


def read_swarm_states(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(stamps_ns [T], positions [T, n, 2], headings [T, n], led_colors [T, n, 3] uint8)."""
    r = read_recording(path)
    return r.stamps_ns, r.positions, r.headings, r.led_colors


def _custom_data(path: Path) -> dict[str, str]:
    import yaml
    meta = path / "metadata.yaml"
    try:
        data = yaml.safe_load(meta.read_text(encoding="utf-8"))
        return dict(data["rosbag2_bagfile_information"].get("custom_data") or {})
    except FileNotFoundError:
        hint = f"; its run was killed before closing it: composed-sim bag repair {path}" \
            if (path / UNFINISHED).exists() else "; not a rosbag2 directory"
        raise RecordingError(f"{path}: no metadata.yaml{hint}") from None
    except Exception as e:    # noqa: BLE001 - rosbags' reader errors and file-system errors alike
        raise RecordingError(f"{meta}: unreadable rosbag2 metadata: {e}") from None


def _decode_state(msg: Any, path: Path, ns: int) -> np.ndarray:
    layout = [(f.name, f.offset, f.datatype) for f in msg.fields]
    expected = [(name, STATE_DTYPE.fields[name][1], None) for name in STATE_DTYPE.names]
    if [(a, b) for a, b, _ in layout] != [(a, b) for a, b, _ in expected] \
            or msg.point_step != STATE_DTYPE.itemsize or msg.is_bigendian:
        raise RecordingError(f"{path}: {SWARM_STATE_TOPIC} at {ns} ns: unexpected point layout "
                             f"{[(a, b) for a, b, _ in layout]} (point_step {msg.point_step})")
    return np.frombuffer(np.asarray(msg.data, dtype=np.uint8).tobytes(), dtype=STATE_DTYPE,
                         count=msg.width * msg.height)
