"""Publishing a ROS message type that has no Python package here, as serialized bytes.

``tf2_msgs/msg/TFMessage`` (tf's type) is not among the ROS 2 packages published as wheels, so
rclpy cannot create a publisher for it: a publisher needs the type's *type support*, a C struct
that tells the middleware the type's DDS name, its hash and how to (de)serialise it. For a
publisher of already serialized CDR bytes (``Publisher.publish(bytes)``) and a subscription that
takes bytes (``raw=True``), Fast DDS needs only the name and the hash from it: the bytes are
written and read as they are. ``raw_message_type`` builds such a type support with ctypes, in
the layout of ``rosidl_typesupport_fastrtps_c`` (the headers ship with the ROS wheels:
``rosidl_runtime_c/message_type_support_struct.h`` and
``rosidl_typesupport_fastrtps_cpp/message_type_support.h``), and wraps it in a class that rclpy
takes as a message type. Its (de)serialisation callbacks refuse: a Python message object of the
type cannot be published or taken, only bytes. Other processes see an ordinary topic of the
type, with the type's real hash, and any subscriber of the type (tf2, RViz, Foxglove's bridge,
a recorder) matches it.
"""
from __future__ import annotations

import ctypes
from functools import lru_cache

_FASTRTPS_C = b"rosidl_typesupport_fastrtps_c"   # the identifier rmw_fastrtps_cpp asks for first
_INTROSPECTION_C = b"rosidl_typesupport_introspection_c"   # … and for the type's XTypes description
_ROS_TYPE_MESSAGE = 18                            # rosidl_typesupport_introspection_c__ROS_TYPE_MESSAGE
_SEQUENCE_STRUCT_SIZE = 24                        # a C sequence field: data pointer, size, capacity
_UNBOUNDED = 0x00                                 # ROSIDL_TYPESUPPORT_FASTRTPS_UNBOUNDED_TYPE

_Serialize = ctypes.CFUNCTYPE(ctypes.c_bool, ctypes.c_void_p, ctypes.c_void_p)
_SerializedSize = ctypes.CFUNCTYPE(ctypes.c_uint32, ctypes.c_void_p)
_MaxSerializedSize = ctypes.CFUNCTYPE(ctypes.c_size_t, ctypes.POINTER(ctypes.c_char))


class _Callbacks(ctypes.Structure):      # message_type_support_callbacks_t
    _fields_ = [("message_namespace", ctypes.c_char_p), ("message_name", ctypes.c_char_p),
                ("cdr_serialize", _Serialize), ("cdr_deserialize", _Serialize),
                ("get_serialized_size", _SerializedSize), ("max_serialized_size", _MaxSerializedSize),
                ("key_callbacks", ctypes.c_void_p)]


class _TypeHash(ctypes.Structure):       # rosidl_type_hash_t
    _fields_ = [("version", ctypes.c_uint8), ("value", ctypes.c_uint8 * 32)]


class _TypeSupport(ctypes.Structure):    # rosidl_message_type_support_t
    pass


_Handle = ctypes.CFUNCTYPE(ctypes.c_void_p, ctypes.POINTER(_TypeSupport), ctypes.c_char_p)
_Getter = ctypes.CFUNCTYPE(ctypes.c_void_p, ctypes.POINTER(_TypeSupport))
_TypeSupport._fields_ = [("typesupport_identifier", ctypes.c_char_p), ("data", ctypes.c_void_p),
                         ("func", _Handle), ("get_type_hash_func", _Getter),
                         ("get_type_description_func", _Getter),
                         ("get_type_description_sources_func", _Getter)]

class _Member(ctypes.Structure):         # rosidl_typesupport_introspection_c__MessageMember
    _fields_ = [("name", ctypes.c_char_p), ("type_id", ctypes.c_uint8), ("string_upper_bound", ctypes.c_size_t),
                ("members", ctypes.c_void_p), ("is_key", ctypes.c_bool), ("is_array", ctypes.c_bool),
                ("array_size", ctypes.c_size_t), ("is_upper_bound", ctypes.c_bool), ("offset", ctypes.c_uint32),
                ("default_value", ctypes.c_void_p), ("size_function", ctypes.c_void_p),
                ("get_const_function", ctypes.c_void_p), ("get_function", ctypes.c_void_p),
                ("fetch_function", ctypes.c_void_p), ("assign_function", ctypes.c_void_p),
                ("resize_function", ctypes.c_void_p)]


class _Members(ctypes.Structure):        # rosidl_typesupport_introspection_c__MessageMembers
    _fields_ = [("message_namespace", ctypes.c_char_p), ("message_name", ctypes.c_char_p),
                ("member_count", ctypes.c_uint32), ("size_of", ctypes.c_size_t),
                ("has_any_key_member", ctypes.c_bool), ("members", ctypes.POINTER(_Member)),
                ("init_function", ctypes.c_void_p), ("fini_function", ctypes.c_void_p)]


class _String(ctypes.Structure):         # rosidl_runtime_c__String
    _fields_ = [("data", ctypes.c_char_p), ("size", ctypes.c_size_t), ("capacity", ctypes.c_size_t)]


class _Sequence(ctypes.Structure):       # any rosidl_runtime_c sequence
    _fields_ = [("data", ctypes.c_void_p), ("size", ctypes.c_size_t), ("capacity", ctypes.c_size_t)]


class _TypeDescription(ctypes.Structure):   # rosidl_runtime_c__type_description__TypeDescription
    _fields_ = [("type_name", _String), ("fields", _Sequence), ("referenced_type_descriptions", _Sequence)]


_capsule_pointer = ctypes.pythonapi.PyCapsule_GetPointer
_capsule_pointer.restype = ctypes.c_void_p
_capsule_pointer.argtypes = [ctypes.py_object, ctypes.c_char_p]
_capsule = ctypes.pythonapi.PyCapsule_New
_capsule.restype = ctypes.py_object
_capsule.argtypes = [ctypes.c_void_p, ctypes.c_char_p, ctypes.c_void_p]


class _RawMessageMeta(type):
    """What rclpy looks up on a message class's metaclass. Only the type support is real; the
    converters are never called for a type that travels as bytes."""
    _TYPE_SUPPORT = None
    _CREATE_ROS_MESSAGE = _CONVERT_FROM_PY = _CONVERT_TO_PY = _DESTROY_ROS_MESSAGE = object()

    @classmethod
    def __import_type_support__(cls):
        pass


@lru_cache(maxsize=None)
def raw_message_type(type_name: str, rihs01: str, sequence_of: type) -> type:
    """A message class for ``type_name`` (``tf2_msgs/msg/TFMessage``), a message with one field,
    a sequence of ``sequence_of`` (an installed message type, e.g. ``TransformStamped``), whose
    publishers publish CDR bytes and whose ``raw=True`` subscriptions take them. ``rihs01``: the
    type's hash (``RIHS01_<64 hex digits>``, as ``ros2 topic info -v`` prints it). Cached: one
    per type; the C structures live as long as the process (the middleware keeps pointers)."""
    package, _, name = type_name.split("/")
    if not rihs01.startswith("RIHS01_") or len(rihs01) != 7 + 64:
        raise ValueError(f"{type_name}: not a RIHS01 type hash: {rihs01!r}")
    refuse = _Serialize(lambda message, cdr: False)

    def max_serialized_size(bounds_info):
        bounds_info[0] = bytes([_UNBOUNDED])
        return 0
    sizes = (_SerializedSize(lambda message: 0), _MaxSerializedSize(max_serialized_size))
    callbacks = _Callbacks(f"{package}::msg".encode(), name.encode(), refuse, refuse, *sizes, None)
    # The introspection description, from which Fast DDS builds the type's XTypes object: one
    # unbounded sequence field whose element type's description comes with its package.
    field = _Member(name=_sequence_field(type_name), type_id=_ROS_TYPE_MESSAGE,
                    members=_introspection_of(sequence_of), is_array=True)
    members = _Members(f"{package}__msg".encode(), name.encode(), 1, _SEQUENCE_STRUCT_SIZE, False,
                       ctypes.pointer(field), None, None)
    type_hash = _TypeHash(1, (ctypes.c_uint8 * 32)(*bytes.fromhex(rihs01[7:])))
    fastrtps, introspection = _TypeSupport(), _TypeSupport()
    handles = {_FASTRTPS_C: ctypes.addressof(fastrtps), _INTROSPECTION_C: ctypes.addressof(introspection)}
    # rcl files every type a node uses under its hash, with its description, for the node's
    # ~/get_type_description service: the type's name and no fields (the nodes that use these
    # types run without that service, quiet_node_options), and no sources.
    description = _TypeDescription(_String(type_name.encode(), len(type_name), len(type_name) + 1))
    no_sources = _Sequence()
    functions = (_Handle(lambda ts, identifier: handles.get(identifier)),
                 _Getter(lambda ts: ctypes.addressof(type_hash)), _Getter(lambda ts: ctypes.addressof(description)),
                 _Getter(lambda ts: ctypes.addressof(no_sources)))
    for support, identifier, data in ((fastrtps, _FASTRTPS_C, callbacks), (introspection, _INTROSPECTION_C, members)):
        support.typesupport_identifier = identifier
        support.data = ctypes.addressof(data)
        support.func, support.get_type_hash_func = functions[0], functions[1]
        support.get_type_description_func, support.get_type_description_sources_func = functions[2], functions[3]
    meta = type(f"{name}Meta", (_RawMessageMeta,), {
        "_TYPE_SUPPORT": _capsule(ctypes.addressof(fastrtps), None, None),
        "_keep_alive": (refuse, sizes, callbacks, field, members, type_hash, description, no_sources, fastrtps, introspection,
                        functions)})
    return meta(name, (), {"__module__": f"{package}.msg", "__doc__": f"{type_name}, as serialized bytes only"})


def _sequence_field(type_name: str) -> bytes:
    return {"tf2_msgs/msg/TFMessage": b"transforms"}[type_name]


def _introspection_of(msg_type: type) -> int:
    """The C introspection type support of an installed message type (its package loads it)."""
    msg_type.__class__.__import_type_support__()
    dispatch = ctypes.cast(_capsule_pointer(msg_type.__class__._TYPE_SUPPORT, None), ctypes.POINTER(_TypeSupport))
    found = dispatch.contents.func(dispatch, _INTROSPECTION_C)
    if not found:
        raise RuntimeError(f"no introspection type support for {msg_type.__name__}")
    return found
