"""Exception hierarchy: one root, one subclass per layer, so callers can catch at the right level.

CLIs turn any ``AtsvoError`` into a one-line message and exit code 1; nodes log, count and recover.
"""
from __future__ import annotations


class AtsvoError(Exception):
    """Root of every error raised on purpose by atsvo_ros."""


class ConfigError(AtsvoError, ValueError):
    """A configuration value is missing, of the wrong type or out of its allowed range."""


class CalibrationError(AtsvoError, ValueError):
    """A camera model or extrinsic could not be built from the given calibration."""


class GeometryError(AtsvoError, ValueError):
    """Invalid input to an SE(3)/SO(3) operation (wrong shape, not a rotation, NaN)."""


class DecodeError(AtsvoError):
    """An event message or file could not be decoded (unknown encoding, truncated buffer, ...).

    ``kind`` names the problem in a word (``truncated``, ``unknown_encoding``, ``time_range``,
    ``bad_header``, ``malformed``), so that decoders can count and rate-limit reports per kind.
    """

    def __init__(self, message: str, kind: str = "malformed") -> None:
        super().__init__(message)
        self.kind = kind

    def __reduce__(self):  # keep ``kind`` through pickling (multiprocessing, logging handlers)
        return (type(self), (str(self), self.kind))


class ImuError(AtsvoError, ValueError):
    """IMU samples are inconsistent (array shapes, unsorted stamps) or do not cover a requested interval."""


class ImageError(AtsvoError):
    """An image message has an unsupported encoding or inconsistent size."""


class BagError(AtsvoError):
    """A bag could not be opened, or lacks a topic that the replay needs."""


class DatasetError(BagError):
    """A dataset folder (e.g. TUM RGB-D) lacks a file or holds a malformed line (named with its line number)."""


class TransformError(AtsvoError, ValueError):
    """A pose or transform read from a message is unusable (NaN/inf, zero-norm quaternion).

    Carries ``topic``, ``parent``/``child`` frames and ``stamp_ns`` so that a caller can decide to
    skip the message or stop, and report which one it was.
    """

    def __init__(self, message: str, topic: str = "", parent: str = "", child: str = "",
                 stamp_ns: int | None = None) -> None:
        super().__init__(message)
        self.topic, self.parent, self.child, self.stamp_ns = topic, parent, child, stamp_ns

    def __reduce__(self):
        return (type(self), (str(self), self.topic, self.parent, self.child, self.stamp_ns))


class TrajectoryError(AtsvoError):
    """A trajectory file is malformed, or two trajectories cannot be associated."""


class EvaluationError(AtsvoError):
    """Metrics cannot be computed (too few matched poses, degenerate alignment, ...)."""


class TrackingError(AtsvoError):
    """The tracker was given inconsistent input (internal failures are reported as a status)."""


class SimulationError(AtsvoError):
    """A synthetic sequence could not be generated with the requested settings."""


class WireError(AtsvoError):
    """A message of the atsvo wire format (keyframe requests, map snapshots between processes) is malformed."""


class OutputError(AtsvoError):
    """An output path cannot be written (a file where a folder is needed, no permission, the input itself)."""


class RecordError(AtsvoError):
    """A run cannot be recorded as a bag (the output exists, a bad file name, no mcap writer in rosbags)."""
