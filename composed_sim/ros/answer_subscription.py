"""A robot's ``cmd_vel`` subscription that tells who published each answer.

The simulator accepts a robot's answers from that robot's controller only: a ``cmd_vel`` that
another process publishes on the robot's topic (a second run in the same ROS domain, a stray
teleop node) must never move the robot (docs/faults.md). The middleware knows each sample's
writer: rcl's take fills ``rmw_message_info_t.publisher_gid``. rclpy 7.1's take returns the
timestamps and sequence numbers of that struct but not the GID, so the answers are taken through
rcl with ctypes (``rcl_take_serialized_message``, the serialized bytes the simulator decodes
anyway) with the structs laid out as in the rmw and rcutils headers that ship with the ROS wheels
(``rmw/types.h``, ``rcutils/types/uint8_array.h``).

Every executor takes through it: the subscription is an rclpy ``Waitable``, which the stock
executors and the events executor drive through a wait set, and the lockstep executor calls its
``dispatch_ready`` in its walk, as it takes an ordinary subscription's message.
"""
from __future__ import annotations

import ctypes
import threading
import time
from typing import Callable, Optional, Sequence

from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node
from rclpy.publisher import Publisher
from rclpy.qos import QoSProfile
from rclpy.type_support import check_is_valid_msg_type
from rclpy.waitable import NumberOfEntities, Waitable

from composed_sim.ros import contract as c
from composed_sim.ros.in_process import Inbox

_GID_BYTES = 16                      # RMW_GID_STORAGE_SIZE
NODE_NAME_UNKNOWN = "_NODE_NAME_UNKNOWN_"  # the graph's node name for an endpoint whose node is not known yet
# How long noting the controllers waits for the ROS graph to list a matched controller's cmd_vel
# publisher (the graph and the match are updated by the same discovery, a moment apart at most).
NOTE_WAIT_S = 2.0
_RET_OK, _RET_TAKE_FAILED = 0, 401   # RCL_RET_OK, RCL_RET_SUBSCRIPTION_TAKE_FAILED (nothing to take)


class _Allocator(ctypes.Structure):          # rcutils_allocator_t
    _fields_ = [("allocate", ctypes.c_void_p), ("deallocate", ctypes.c_void_p), ("reallocate", ctypes.c_void_p),
                ("zero_allocate", ctypes.c_void_p), ("state", ctypes.c_void_p)]


class _Bytes(ctypes.Structure):              # rcutils_uint8_array_t (= rcl_serialized_message_t)
    _fields_ = [("buffer", ctypes.c_void_p), ("buffer_length", ctypes.c_size_t),
                ("buffer_capacity", ctypes.c_size_t), ("allocator", _Allocator)]


class _Gid(ctypes.Structure):                # rmw_gid_t
    _fields_ = [("implementation_identifier", ctypes.c_char_p), ("data", ctypes.c_uint8 * _GID_BYTES)]


class _MessageInfo(ctypes.Structure):        # rmw_message_info_t
    _fields_ = [("source_timestamp", ctypes.c_int64), ("received_timestamp", ctypes.c_int64),
                ("publication_sequence_number", ctypes.c_uint64), ("reception_sequence_number", ctypes.c_uint64),
                ("publisher_gid", _Gid), ("from_intra_process", ctypes.c_bool)]


# rclpy's extension module has loaded librcl (and, as its dependencies, rcutils and the rmw), so
# these open the copies already in the process.
_rcl = ctypes.CDLL("librcl.so")
_rcutils = ctypes.CDLL("librcutils.so")
_take = _rcl.rcl_take_serialized_message
_take.argtypes = [ctypes.c_void_p, ctypes.POINTER(_Bytes), ctypes.POINTER(_MessageInfo), ctypes.c_void_p]
_take.restype = ctypes.c_int
_rcl.rcl_publisher_get_rmw_handle.argtypes = [ctypes.c_void_p]
_rcl.rcl_publisher_get_rmw_handle.restype = ctypes.c_void_p
# An rmw function, found through librcl's handle: dlsym searches a library's dependencies too.
_rcl.rmw_get_gid_for_publisher.argtypes = [ctypes.c_void_p, ctypes.POINTER(_Gid)]
_rcl.rmw_get_gid_for_publisher.restype = ctypes.c_int
_rcutils.rcutils_get_default_allocator.restype = _Allocator
_rcutils.rcutils_uint8_array_init.argtypes = [ctypes.POINTER(_Bytes), ctypes.c_size_t, ctypes.POINTER(_Allocator)]
_rcutils.rcutils_uint8_array_fini.argtypes = [ctypes.POINTER(_Bytes)]


class _ErrorString(ctypes.Structure):        # rcutils_error_string_t, returned by value
    _fields_ = [("text", ctypes.c_char * 1024)]


_rcutils.rcutils_get_error_string.restype = _ErrorString


def _error_text() -> str:
    """rcutils' error message of the last failed call, which it then forgets."""
    reason = _rcutils.rcutils_get_error_string().text.decode(errors="replace")
    _rcutils.rcutils_reset_error()
    return reason


def cmd_vel_gids(node: Node, robot: str) -> list[bytes]:
    """The GIDs of ``node``'s publishers on ``robot``'s cmd_vel: what its host tells the simulator
    (``SimulatorNode.note_controllers``), from the publishers themselves, not the ROS graph."""
    topic = c.topic_name(robot, c.CMD_VEL)
    return [publisher_gid(publisher) for publisher in node.publishers if publisher.topic_name == topic]


def publisher_gid(publisher: Publisher) -> bytes:
    """A publisher's GID, as the ROS graph and each message's info give it."""
    gid = _Gid()
    with publisher.handle:
        rmw_publisher = _rcl.rcl_publisher_get_rmw_handle(publisher.handle.pointer)
        if _rcl.rmw_get_gid_for_publisher(rmw_publisher, ctypes.byref(gid)) != _RET_OK:
            raise RuntimeError(f"rmw_get_gid_for_publisher failed on {publisher.topic_name}: {_error_text()}")
    return bytes(gid.data)


def gid_text(gid: bytes) -> str:
    """A GID as ``ros2 topic info --verbose`` prints it."""
    return ".".join(f"{b:02x}" for b in gid)


class AnswerSubscription(Waitable):
    """A subscription taken as serialized bytes with the publisher's GID: ``callback(data, gid)``."""

    def __init__(self, node: Node, msg_type: type, topic: str, qos: QoSProfile,
                 callback: Callable[[bytes, bytes], None]):
        super().__init__(node.default_callback_group)
        check_is_valid_msg_type(msg_type)      # also loads the type's support, as create_subscription does
        with node.handle:
            self.handle = _rclpy.Subscription(node.handle, msg_type, topic, qos.get_c_qos_profile())
        self.topic_name = self.handle.get_topic_name()
        self.msg_type, self.qos = msg_type, qos
        # (bytes, GID) of answers its controller's publishers hand over in process (ros/in_process.py)
        self.inbox = Inbox(qos.depth, None, self.handle.get_publisher_count)
        self._pointer = self.handle.pointer
        self._callback = callback
        self._message = _Bytes()
        allocator = _rcutils.rcutils_get_default_allocator()
        if _rcutils.rcutils_uint8_array_init(ctypes.byref(self._message), 128, ctypes.byref(allocator)) != _RET_OK:
            raise MemoryError(f"no buffer for {self.topic_name}'s messages")
        self._info = _MessageInfo()
        self._args = (self._pointer, ctypes.byref(self._message), ctypes.byref(self._info), None)
        self._gid_at = ctypes.addressof(self._info) + _MessageInfo.publisher_gid.offset + _Gid.data.offset
        self._lock = threading.Lock()          # a take against the buffer's release
        self._wait_set_index: Optional[int] = None
        node.add_waitable(self)

    def get_publisher_count(self) -> int:
        return self.handle.get_publisher_count()

    def _take(self) -> Optional[tuple[bytes, bytes]]:
        """The next message's bytes and its publisher's GID; None when there is none. Called
        with the lock held (the handle too is destroyed only under it: ``destroy``)."""
        if self._args is None:
            return None
        ret = _take(*self._args)
        if ret == _RET_TAKE_FAILED:
            return None
        if ret != _RET_OK:
            raise RuntimeError(f"taking a message of {self.topic_name} failed: {_error_text()} (rcl {ret})")
        message = self._message
        return ctypes.string_at(message.buffer, message.buffer_length), ctypes.string_at(self._gid_at, _GID_BYTES)

    def dispatch_ready(self) -> int:
        """Take the messages handed over in process, every one (the last answers the tick, as
        through DDS, where they all arrive before the tick closes), and run the callback on each
        (the lockstep executor's walk); then, while DDS may hold one too, one from DDS.

        A message from DDS is taken and handled under the lock: a thread that finds nothing to
        take (the simulator's, before it settles quiet robots) knows that no other thread holds
        an answer taken but not yet handled (a multi-threaded executor's, descheduled between
        the two)."""
        inbox = self.inbox
        handled = self.take_handed_over()
        if handled and inbox.links and not inbox.dds_may_hold():
            return handled
        with self._lock:
            taken = self._take()
            if taken is not None:
                self._callback(*taken)
                return handled + 1
        inbox.emptied()
        return handled

    def take_handed_over(self) -> int:
        """What was handed over in process since the last take, every message (in the walk, and
        before the tick closes, so that an answer published after the walk's last look answers
        this tick, not the next); how many."""
        queue, handled = self.inbox.queue, 0
        while queue:
            self._callback(*queue.popleft())
            handled += 1
        return handled

    def destroy(self, node: Node) -> None:
        node.remove_waitable(self)
        with self._lock:
            self._args = None
            _rcutils.rcutils_uint8_array_fini(ctypes.byref(self._message))
            self.handle.destroy_when_not_in_use()

    # --- the Waitable interface, for executors that wait on a wait set ------------------------

    def __enter__(self):
        self.handle.__enter__()

    def __exit__(self, *exc) -> None:
        self.handle.__exit__(*exc)

    def get_num_entities(self) -> NumberOfEntities:
        return NumberOfEntities(num_subs=1)

    def add_to_wait_set(self, wait_set) -> None:
        self._wait_set_index = wait_set.add_subscription(self.handle)

    def is_ready(self, wait_set) -> bool:
        return wait_set.is_ready("subscription", self._wait_set_index)

    def take_data(self) -> None:
        # The callback runs here, as the message is taken: the events executor would otherwise
        # queue ``execute`` as a task behind whatever else is queued (a hung controller callback,
        # say), and the answer would miss its tick. It is the simulator's own short callback.
        self.dispatch_ready()

    async def execute(self, taken: None) -> None:
        pass


class ControllerPublishers:
    """Per robot, the GIDs of its controller's cmd_vel publishers; answers from any other
    publisher are not the controller's. Every host tells them (``set``), from the publishers
    themselves (``cmd_vel_gids``). A simulator node used without a host notes, when the first
    tick opens, those the ROS graph lists on the robot's topic (``note``), which takes a publisher
    already in the domain then, a controller left over from another run say, for the controller."""

    def __init__(self, node: Node, subscriptions: Sequence[Optional[AnswerSubscription]],
                 answer_types: Sequence[Optional[type]]):
        self._node = node
        self._subscriptions = subscriptions     # the node's lists, filled as answer types become known
        self._answer_types = answer_types
        self._gids: Optional[list[Optional[frozenset[bytes]]]] = None
        self._names: dict[bytes, str] = {}

    @property
    def noted(self) -> bool:
        return self._gids is not None

    def note(self) -> None:
        gids: list[Optional[frozenset[bytes]]] = [None] * len(self._subscriptions)
        deadline = time.monotonic() + NOTE_WAIT_S
        while True:
            for i, sub in enumerate(self._subscriptions):
                if gids[i] is None and sub is not None:
                    type_name = c.type_name(self._answer_types[i])
                    gids[i] = frozenset(graph_gid(info) for info in self._node.get_publishers_info_by_topic(sub.topic_name)
                                        if info.topic_type == type_name) or None
            if all(g is not None or s is None for g, s in zip(gids, self._subscriptions)) or time.monotonic() > deadline:
                break
            time.sleep(0.01)
        # A robot whose publisher the graph never listed (a controller without one fails on its
        # own) stays un-noted: its answers are not checked.
        self._gids = gids

    def set(self, gids: Sequence[Optional[frozenset[bytes]]]) -> None:
        """Per robot, its controller's GIDs (None: not known, its answers are not checked)."""
        self._gids = list(gids)

    def set_one(self, i: int, gids: Optional[frozenset[bytes]]) -> None:
        """Robot i's GIDs, once its nodes made another cmd_vel publisher (a lifecycle node's)."""
        if self._gids is None:
            self._gids = [None] * len(self._subscriptions)
        self._gids[i] = gids

    def accepts(self, i: int, gid: bytes) -> bool:
        """May this publisher answer for robot i? (Anyone, until the controllers are noted.)"""
        gids = None if self._gids is None else self._gids[i]
        return gids is None or gid in gids

    def describe(self, i: int, gid: bytes) -> str:
        """A publisher on robot i's cmd_vel: its node and GID, for a violation."""
        if gid in self._names:
            return self._names[gid]
        infos = [info for info in self._node.get_publishers_info_by_topic(self._subscriptions[i].topic_name)
                 if graph_gid(info) == gid]
        if not infos:
            return f"a publisher the ROS graph does not list (publisher GID {gid_text(gid)})"
        text = publisher_text(infos[0])
        if infos[0].node_name != NODE_NAME_UNKNOWN:     # named for good: kept
            self._names[gid] = text
        return text


def graph_gid(info) -> bytes:
    """The GID of an endpoint the ROS graph lists (a ``TopicEndpointInfo``)."""
    return bytes(info.endpoint_gid)[:_GID_BYTES]


def node_path(info) -> str:
    """The node of an endpoint the ROS graph lists, as ``/namespace/name``."""
    return f"{info.node_namespace.rstrip('/')}/{info.node_name}"


def publisher_text(info) -> str:
    """A publisher the ROS graph lists, for a message: its node and GID. Its node's name arrives
    a moment after the endpoint; until then the GID alone names it."""
    if info.node_name == NODE_NAME_UNKNOWN:
        return f"a node not yet named in the ROS graph (publisher GID {gid_text(graph_gid(info))})"
    return f"node {node_path(info)} (publisher GID {gid_text(graph_gid(info))})"
