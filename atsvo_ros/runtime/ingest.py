"""Event message ingest: decoding event messages, held back until the event camera_info gives the sensor size.

The vectorised decoders (:class:`~atsvo_ros.io.decode.EventDecoder`, one per topic, stateful) need the
event sensor's width and height. When ``event_camera.use_camera_info`` is set and no model was given,
the stream is held (bounded: :attr:`OdometryRuntime.MAX_HELD_EVENT_MSGS
<atsvo_ros.runtime.runtime.OdometryRuntime.MAX_HELD_EVENT_MSGS>` messages or 1 s of stream) until the
camera_info arrives; then the configuration's event camera is used instead. Decoded batches go on to
the runtime's ``add_events`` (the frame assembler), with the message stamp as the point up to which
the stream is complete. This is apart from the runtime because it owns per-topic decoder state and
the event camera model, and nothing else in the runtime needs either.
"""
from __future__ import annotations

from collections import deque
from collections.abc import Callable
from typing import Any

from atsvo_ros.config import AtsvoConfig
from atsvo_ros.core.camera import CameraModel
from atsvo_ros.core.events.batch import EventBatch
from atsvo_ros.io.decode import EventDecoder
from atsvo_ros.io.images import stamp_ns
from atsvo_ros.io.restamp import cdr_stamp_ns
from atsvo_ros.runtime.problems import ProblemLog

#: Where decoded events go: ``add_events(batch, complete_to_ns)``.
EventSink = Callable[[EventBatch, int | None], None]


class EventIngest:
    """Decodes event messages per topic, holding them while the event camera is unknown.

    Attributes:
        camera: The event camera model (None until the event camera_info, when
            ``event_camera.use_camera_info`` is set and no model was given).
    """

    def __init__(self, config: AtsvoConfig, camera: CameraModel | None, add_events: EventSink,
                 problems: ProblemLog, *, max_held_msgs: int) -> None:
        """Create the ingest.

        Args:
            config: The configuration (``event_camera``: the fallback model and ``use_camera_info``).
            camera: The event camera model, or None to wait for the camera_info.
            add_events: Where decoded batches go, with the stamp the stream is complete up to.
            problems: Where problems and the ``event_msgs`` count go.
            max_held_msgs: Event messages held while the camera is unknown before the configuration's is used.
        """
        self.config = config
        self.camera = camera
        self._add_events = add_events
        self._problems = problems
        self._max_held_msgs = int(max_held_msgs)
        self._decoders: dict[str, Any] = {}
        self._held_events: deque[tuple[Any, str, str]] = deque()  # event messages waiting for the event camera

    def set_camera(self, camera: CameraModel | None) -> None:
        """The event camera from its camera_info (None: unusable); decodes the held messages once known.

        Args:
            camera: The event camera model, or None when the camera_info was unusable.
        """
        self.camera = camera
        if self.camera is not None:
            self._decode_held_events()

    def add_msg(self, msg: Any, msgtype: str, topic: str) -> None:
        """One event message, deserialized or as raw CDR bytes (an rclpy ``raw=True`` subscription).

        Args:
            msg: The message object or its serialized bytes.
            msgtype: Its ROS message type (selects the decoder).
            topic: The topic it came on (one decoder per topic).
        """
        if self.camera is None and self.config.event_camera.use_camera_info:
            # The decoder needs the sensor size: hold the stream until the camera_info (bounded).
            self._held_events.append((msg, msgtype, topic))
            first = self._held_events[0][0]
            span_ns = (any_stamp_ns(msg) or 0) - (any_stamp_ns(first) or 0)
            if len(self._held_events) < self._max_held_msgs and span_ns < 1_000_000_000:
                return
            self._problems.report("event_camera_info_missing", f"{topic}: no event camera_info after "
                                  f"{len(self._held_events)} event messages: using event_camera from the "
                                  "configuration")
            self.camera = CameraModel.from_config(self.config.event_camera)
            self._decode_held_events()
            return
        self._decode_event_msg(msg, msgtype, topic)

    @property
    def decoder_stats(self) -> dict[str, Any]:
        """Event decoder statistics per topic (only for messages decoded here)."""
        return {t: d.stats.as_dict() for t, d in self._decoders.items()}

    def _decode_held_events(self) -> None:
        while self._held_events:
            self._decode_event_msg(*self._held_events.popleft())

    def _decode_event_msg(self, msg: Any, msgtype: str, topic: str) -> None:
        dec = self._decoders.get(topic)
        if dec is None:
            cam = self.camera or CameraModel.from_config(self.config.event_camera)
            dec = self._decoders[topic] = EventDecoder(msgtype, 2, cam.width, cam.height)
        self._problems.counters["event_msgs"] += 1
        if isinstance(msg, (bytes, bytearray, memoryview)):
            batch = dec.decode_raw(msg)
            mark = cdr_stamp_ns(msg)
        else:
            batch = dec.decode_message(msg)
            try:
                mark = stamp_ns(msg)
            except (AttributeError, TypeError):
                mark = None
        self._add_events(batch, mark)


def stamp_text(msg: Any) -> str:
    """A message's header stamp for a log line (``"<ns> ns"``, or ``"an unknown stamp"``).

    Args:
        msg: A deserialized message.

    Returns:
        The text.
    """
    try:
        return f"{stamp_ns(msg)} ns"
    except (AttributeError, TypeError, ValueError):
        return "an unknown stamp"


def any_stamp_ns(msg: Any) -> int | None:
    """header.stamp of a message object or of its serialized bytes (None when there is none).

    Args:
        msg: A deserialized message or its CDR bytes.

    Returns:
        The stamp in ns, or None.
    """
    if isinstance(msg, (bytes, bytearray, memoryview)):
        return cdr_stamp_ns(msg)
    try:
        return stamp_ns(msg)
    except (AttributeError, TypeError, ValueError):
        return None


__all__ = ["EventIngest", "EventSink", "any_stamp_ns", "stamp_text"]
