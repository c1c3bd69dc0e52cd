"""Byte layouts of the event messages in ROS 1 and ROS 2 (CDR) serialization, for numpy views.

ROS 1 packs fields without padding (dvs Event = 13 bytes). CDR aligns each primitive to its own
size relative to the start of the payload (after the 4-byte encapsulation header), so in a
``dvs_msgs/Event[]`` the first element starts 4-aligned (x, y, sec, nsec, p at 0, 2, 4, 8, 12)
while every later one starts at 2 mod 4 (at 0, 2, 6, 10, 14, stride 16). :func:`dvs_cdr_layout`
derives this from the alignment rules for any start offset, so encoder and decoder agree.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: (name, size) of the fields of one dvs Event in serialization order
_DVS_FIELDS = (("x", 2), ("y", 2), ("sec", 4), ("nsec", 4), ("p", 1))
ROS1_DVS_EVENT = np.dtype({"names": ["x", "y", "sec", "nsec", "p"],
                           "formats": ["<u2", "<u2", "<u4", "<u4", "u1"],
                           "offsets": [0, 2, 4, 8, 12], "itemsize": 13})


def align(offset: int, size: int) -> int:
    """``offset`` rounded up to a multiple of ``size``."""
    return (offset + size - 1) // size * size


def _place(start: int) -> tuple[tuple[int, ...], int]:
    """Field offsets of one element starting at ``start`` (absolute) and the offset after it."""
    pos = start
    offs = []
    for _, size in _DVS_FIELDS:
        pos = align(pos, size)
        offs.append(pos)
        pos += size
    return tuple(offs), pos


@dataclass(frozen=True)
class DvsCdrLayout:
    """Where the fields of a CDR dvs Event[] are: element 0 apart, elements >= 1 strided."""

    first: tuple[int, ...]   # absolute field offsets of element 0
    rest_start: int          # absolute start of element 1 (its x)
    rest_offsets: tuple[int, ...]  # field offsets of elements >= 1 relative to their x
    stride: int

    def end(self, n: int) -> int:
        """Absolute offset just after the last of ``n`` elements."""
        if n == 0:
            return self.first[0]
        if n == 1:
            return self.first[-1] + 1
        return self.rest_start + (n - 2) * self.stride + self.rest_offsets[-1] + 1

    def dtype(self, big_endian: bool = False) -> np.dtype:
        e = ">" if big_endian else "<"
        return np.dtype({"names": ["x", "y", "sec", "nsec", "p"],
                         "formats": [f"{e}u2", f"{e}u2", f"{e}i4", f"{e}u4", "u1"],
                         "offsets": list(self.rest_offsets), "itemsize": self.stride})


def dvs_cdr_layout(start: int) -> DvsCdrLayout:
    """Layout of a dvs Event[] whose first element begins at CDR offset ``start`` (already 2-aligned)."""
    first, end0 = _place(start)
    s1 = align(end0, 2)
    o1, end1 = _place(s1)
    s2 = align(end1, 2)
    o2, _ = _place(s2)
    rel1 = tuple(o - s1 for o in o1)
    assert rel1 == tuple(o - s2 for o in o2), "CDR dvs layout is not periodic"
    return DvsCdrLayout(first, s1, rel1, s2 - s1)
