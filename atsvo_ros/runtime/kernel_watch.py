"""Kernels compiled after the warm-up: the node's check that no frame pays for numba.

A numba kernel compiles once per argument signature (types and array layouts). The warm-up
(:mod:`atsvo_ros.runtime.warmup`) runs the odometry before the node subscribes, but a path it missed, or
an array that arrives in another layout, compiles mid-run: 1-3 s of compiling with the GIL held, every
thread of the node stalled (or ~10 ms when numba's cache has it). :class:`LateKernels` takes the count of
signatures of every kernel once the node is ready and names those that gained one since.
"""
from __future__ import annotations

import sys

from numba.core.dispatcher import Dispatcher


def kernel_signatures(prefix: str = "atsvo_ros") -> dict[str, int]:
    """Signatures compiled (or loaded from numba's cache) so far, per kernel of the loaded modules under ``prefix``."""
    out: dict[str, int] = {}
    for name, module in list(sys.modules.items()):
        if module is None or not (name == prefix or name.startswith(prefix + ".")):
            continue
        for attr, value in list(vars(module).items()):
            if isinstance(value, Dispatcher) and getattr(value, "__module__", name) == name:
                out[f"{name}.{attr}"] = len(value.signatures)
    return out


class LateKernels:
    """Kernels that gained a signature after :meth:`__init__` (call it when the node is ready)."""

    def __init__(self, prefix: str = "atsvo_ros") -> None:
        self.prefix = prefix
        self._ready = kernel_signatures(prefix)
        self._reported: set[str] = set()

    def new(self) -> list[str]:
        """Kernels compiled since the node was ready and not returned before (each is named once)."""
        late = [k for k, n in kernel_signatures(self.prefix).items()
                if n > self._ready.get(k, 0) and k not in self._reported]
        self._reported.update(late)
        return sorted(late)

    @property
    def count(self) -> int:
        """How many kernels :meth:`new` has named so far."""
        return len(self._reported)


__all__ = ["LateKernels", "kernel_signatures"]
