"""rosbags typestores that know the event-camera message types (and tf2_msgs for ROS 1).

The standard stores lack event_camera_msgs, dvs_msgs and dv_ros2_msgs; their definitions are
registered here from the ``.msg`` texts so that the simulator can write and the replay can read
them without any ROS installation. ROS 1 definitions use ``time``/``Header``, ROS 2 ones
``builtin_interfaces/Time``/``std_msgs/Header``.
"""
from __future__ import annotations

from functools import lru_cache
from typing import Any

from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

_EVENT_PACKET = """std_msgs/Header header
uint32 height
uint32 width
uint64 seq
uint64 time_base
string encoding
bool is_bigendian
uint8[] events
"""

_DVS_EVENT_ROS1 = "uint16 x\nuint16 y\ntime ts\nbool polarity\n"
_DVS_EVENT_ROS2 = "uint16 x\nuint16 y\nbuiltin_interfaces/Time ts\nbool polarity\n"


def _array(event_type: str) -> str:
    return f"std_msgs/Header header\nuint32 height\nuint32 width\n{event_type}[] events\n"


#: name -> (ROS 1 definition, ROS 2 definition)
DEFINITIONS: dict[str, tuple[str, str]] = {
    "event_camera_msgs/msg/EventPacket": (_EVENT_PACKET, _EVENT_PACKET),
    # Legacy name of EventPacket (ros-event-camera before 2023), same fields.
    "event_array_msgs/msg/EventArray": (_EVENT_PACKET, _EVENT_PACKET),
    "dvs_msgs/msg/Event": (_DVS_EVENT_ROS1, _DVS_EVENT_ROS2),
    "dvs_msgs/msg/EventArray": (_array("dvs_msgs/Event"), _array("dvs_msgs/Event")),
    "dv_ros_msgs/msg/Event": (_DVS_EVENT_ROS1, _DVS_EVENT_ROS2),
    "dv_ros_msgs/msg/EventArray": (_array("dv_ros_msgs/Event"), _array("dv_ros_msgs/Event")),
    "dv_ros2_msgs/msg/Event": (_DVS_EVENT_ROS1, _DVS_EVENT_ROS2),
    "dv_ros2_msgs/msg/EventArray": (_array("dv_ros2_msgs/Event"), _array("dv_ros2_msgs/Event")),
    # /tf_static: in rosbags' ROS 2 store already, missing from its ROS 1 (Noetic) store.
    "tf2_msgs/msg/TFMessage": ("geometry_msgs/TransformStamped[] transforms\n",) * 2,
}

EVENT_MSGTYPES = frozenset(n for n in DEFINITIONS if n.endswith(("EventPacket", "EventArray")))


@lru_cache(maxsize=4)
def typestore(ros_version: int = 2) -> Any:
    """A rosbags typestore (ROS 2 Jazzy or ROS 1 Noetic) with the event types registered."""
    store = get_typestore(Stores.ROS2_JAZZY if ros_version == 2 else Stores.ROS1_NOETIC)
    register_event_types(store, ros_version)
    return store


def register_event_types(store: Any, ros_version: int = 2) -> None:
    """Add the event-camera message types to an existing typestore (e.g. an AnyReader's)."""
    types: dict[str, Any] = {}
    for name, (ros1, ros2) in DEFINITIONS.items():
        if name in store.fielddefs:
            continue
        types.update(get_types_from_msg(ros1 if ros_version == 1 else ros2, name))
    if types:
        store.register(types)


def transient_local_qos() -> Any:
    """The offered QoS of a latched topic (/tf_static, a map) in a ROS 2 bag: reliable, transient local, depth 1.

    ``ros2 bag play`` offers it again, so a late subscriber (RViz, tf2) still gets the message.
    """

    never = QosTime(sec=0x7FFFFFFF, nsec=0xFFFFFFFF)
    return Qos(QosHistory.KEEP_LAST, 1, QosReliability.RELIABLE, QosDurability.TRANSIENT_LOCAL, never, never,
               QosLiveliness.AUTOMATIC, never, False)
