"""What a recording holds: its topics' types and the swarm state's point layout, the colours packed
into it, and the message definitions and type hashes that a bag's schemas (and a Foxglove server)
give, from rosbags' ROS 2 Jazzy typestore or an installed interface package's .msg file."""
from __future__ import annotations

import functools
import os
import re
import sys
from pathlib import Path
from typing import Any

import numpy as np

from composed_sim.ros.global_topics import CLOCK_TOPIC, SWARM_STATE_TOPIC
from composed_sim.ros.global_topics import WORLD_FRAME as FRAME_ID

__all__ = ["CLOCK_TOPIC", "SWARM_STATE_TOPIC", "FRAME_ID"]    # the recording's own topics and frame, re-exported

SWARM_STATE_TYPE = "sensor_msgs/msg/PointCloud2"
CLOCK_TYPE = "rosgraph_msgs/msg/Clock"

# One point per robot; 40 bytes keeps every float64 8-byte aligned from point to point.
STATE_DTYPE = np.dtype([("x", "<f8"), ("y", "<f8"), ("z", "<f8"), ("yaw", "<f8"),
                        ("rgb", "<u4"), ("id", "<u4")])

CUSTOM_PREFIX = "composed_sim."     # of our custom_data keys
NS_PER_S = 1_000_000_000
UNFINISHED = "unfinished.yaml"      # the custom_data of a recording not yet closed


class RecordingError(Exception):
    """A recording that cannot be written or read; the message names the bag and the problem."""


# --- colours -----------------------------------------------------------------------------

def pack_rgb(colors: np.ndarray) -> np.ndarray:
    """[n, 3] uint8 → [n] uint32 0x00RRGGBB."""
    c = colors.astype(np.uint32)
    return (c[:, 0] << 16) | (c[:, 1] << 8) | c[:, 2]


def unpack_rgb(rgb: np.ndarray) -> np.ndarray:
    """[...] uint32 0x00RRGGBB → [..., 3] uint8."""
    rgb = np.asarray(rgb, dtype=np.uint32)
    return np.stack([(rgb >> 16) & 0xFF, (rgb >> 8) & 0xFF, rgb & 0xFF], axis=-1).astype(np.uint8)


# --- message types -----------------------------------------------------------------------

def ros_type_name(msg: Any) -> str:
    """'geometry_msgs/msg/TwistStamped' for an rclpy message (or its class)."""
    cls = msg if isinstance(msg, type) else type(msg)
    parts = cls.__module__.split(".")
    if len(parts) < 2 or parts[1] not in ("msg", "srv", "action"):
        raise ValueError(f"not an rclpy message: {cls.__module__}.{cls.__qualname__}")
    return f"{parts[0]}/{parts[1]}/{cls.__name__}"


def new_typestore():
    from rosbags.typesys import Stores, get_typestore
    return get_typestore(Stores.ROS2_JAZZY)


@functools.lru_cache(maxsize=None)
def message_definition(msgtype: str) -> tuple[str, str]:
    """(the ``ros2msg`` definition with its dependencies, the RIHS01 type hash) of a ROS 2
    message type: what a bag's schema holds, and what a Foxglove server advertises."""
    typestore = _definitions_typestore()
    if msgtype not in typestore.fielddefs:
        _ensure_type(typestore, msgtype)
    msgdef, _ = typestore.generate_msgdef(msgtype, ros_version=2)   # milliseconds: once per type
    return msgdef, typestore.hash_rihs01(msgtype)


@functools.lru_cache(maxsize=1)
def _definitions_typestore():
    return new_typestore()


def _interface_dirs() -> list[Path]:
    """Where installed interface packages keep their .msg files (share/<pkg>/msg)."""
    prefixes = [p for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    prefixes.append(sys.prefix)
    return [Path(p) / "share" for p in prefixes]


def _ensure_type(typestore, name: str) -> None:
    """Register ``name`` (and the types it uses) from its .msg file if the typestore lacks it."""
    from rosbags.typesys import get_types_from_msg

    pending, found = [name], {}
    while pending:
        typ = pending.pop()
        if typ in typestore.fielddefs or typ in found:
            continue
        pkg, kind, short = typ.split("/")
        path = next((d / pkg / kind / f"{short}.msg" for d in _interface_dirs()
                     if (d / pkg / kind / f"{short}.msg").is_file()), None)
        if path is None:
            raise RecordingError(f"message type {typ}: not in the rosbags typestore and no "
                                 f"{pkg}/{kind}/{short}.msg under {', '.join(map(str, _interface_dirs()))}")
        parsed = get_types_from_msg(path.read_text(encoding="utf-8"), typ)
        found.update(parsed)
        pending += [t for t in _referenced_types(parsed) if t not in typestore.fielddefs]
    typestore.register(found)


def _referenced_types(typesdict: dict) -> set[str]:
    """Every 'pkg/msg/Type' named inside parsed field definitions."""
    out: set[str] = set()
    stack: list = list(typesdict.values())
    while stack:
        item = stack.pop()
        if isinstance(item, str):
            if re.fullmatch(r"[A-Za-z]\w*/(msg|srv|action)/\w+", item):
                out.add(item)
        elif isinstance(item, (tuple, list)):
            stack.extend(item)
    return out
