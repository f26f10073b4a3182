"""A ROS message's own copy, as a subscriber or a service in another process would get it.

Calls between hosted nodes are handed over in process (hosting/services.py): the server must get
a request the client can no longer change, and the client a response the server can no longer
change, as if both had crossed DDS. Serializing and deserializing does that but costs about
ten times a field-by-field copy (docs/speed.md), so each message class gets a copier, built once
from its generated slots and field types: nested messages are copied recursively, sequences and
arrays are copied, numbers and strings (immutable) are shared.
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


@functools.cache
def _copier(cls: type) -> Callable:
    slots = [s for s in cls.__slots__ if s != "_check_fields"]
    kinds = [_kind(t) for t in cls.SLOT_TYPES]
    plain = [s for s, k in zip(slots, kinds) if k == "plain"]
    nested = [s for s, k in zip(slots, kinds) if k == "message"]
    sequences = [(s, k == "messages") for s, k in zip(slots, kinds) if k in ("sequence", "messages")]
    new = cls.__new__

    def copy(msg):
        out = new(cls)
        out._check_fields = msg._check_fields
        for slot in plain:
            setattr(out, slot, getattr(msg, slot))
        for slot in nested:
            setattr(out, slot, copy_message(getattr(msg, slot)))
        for slot, of_messages in sequences:
            setattr(out, slot, _copy_sequence(getattr(msg, slot), of_messages))
        return out
    return copy


def _kind(slot_type) -> str:
    if isinstance(slot_type, NamespacedType):
        return "message"
    if isinstance(slot_type, AbstractNestedType):
        return "messages" if isinstance(slot_type.value_type, NamespacedType) else "sequence"
    return "plain"


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
