"""A ROS message's own copy, as a subscriber or a service in another process would get it.

Calls between hosted nodes are handed over in process (hosting/calls/directory.py): the server must get
a request the client can no longer change, and the client a response the server can no longer
change, as if both had crossed DDS. Serializing and deserializing does that, at a higher cost than
a field-by-field copy, so each message class gets a copier, generated once from its slots
and field types (as ``dataclasses`` generates its methods): nested messages are copied by their
own copiers, sequences and arrays are copied, numbers and strings (immutable) are shared.
"""
from __future__ import annotations

import array
import functools
from typing import Callable

import numpy as np
from rosidl_parser.definition import AbstractNestedType, NamespacedType


def copy_message(msg):
    """A deep copy of ``msg`` (any generated ROS message object)."""
    return _copier(msg.__class__)(msg)


def new_message(cls: type):
    """``cls()``, a message of default values, as a copy of one made once (a generated message's
    constructor checks every keyword and builds every nested message)."""
    return _copier(cls)(_default(cls))


@functools.cache
def _default(cls: type):
    return cls()


@functools.cache
def _copier(cls: type) -> Callable:
    lines = ["def copy(msg):", "    out = new(cls)", "    out._check_fields = msg._check_fields"]
    for slot, slot_type in zip((s for s in cls.__slots__ if s != "_check_fields"), cls.SLOT_TYPES):
        if isinstance(slot_type, NamespacedType):
            lines.append(f"    value = msg.{slot}")
            lines.append(f"    out.{slot} = copier(value.__class__)(value)")
        elif isinstance(slot_type, AbstractNestedType):
            of_messages = isinstance(slot_type.value_type, NamespacedType)
            lines.append(f"    out.{slot} = copy_sequence(msg.{slot}, {of_messages})")
        else:
            lines.append(f"    out.{slot} = msg.{slot}")
    lines.append("    return out")
    scope = {"new": cls.__new__, "cls": cls, "copier": _copier, "copy_sequence": _copy_sequence}
    exec("\n".join(lines), scope)       # noqa: S102 - code generated from the class's own slot names
    return scope["copy"]


def _copy_sequence(value, of_messages: bool):
    if of_messages:
        return [copy_message(m) for m in value]
    if isinstance(value, np.ndarray):
        return value.copy()
    if isinstance(value, array.array):
        return value[:]
    if isinstance(value, list):
        return list(value)
    return value            # bytes, str: immutable
