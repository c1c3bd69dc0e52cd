"""What this Python environment gives the package: library versions and the state of the numba kernels.

``atsvo-info`` prints it; the tests use :func:`numba_kernels` to check every kernel for calls that
need SciPy inside numba (its LAPACK/BLAS bindings), which the runtime dependencies do not include.
"""
from __future__ import annotations

import importlib
import importlib.metadata
import os
import pkgutil
from dataclasses import dataclass
from types import ModuleType
from typing import Any

import cv2  # the wheel may be opencv-python or -contrib instead of -headless
from numba.core.registry import CPUDispatcher

import atsvo_ros

#: Distributions reported by ``atsvo-info`` (None = not installed).
LIBRARIES = ("numpy", "numba", "llvmlite", "opencv-python-headless", "rosbags", "scipy", "matplotlib")

#: Subpackages whose modules are scanned for kernels (nodes need rclpy, tools hold none).
_KERNEL_PACKAGES = ("atsvo_ros.core", "atsvo_ros.io", "atsvo_ros.sim", "atsvo_ros.eval")


def library_versions() -> dict[str, str | None]:
    """Installed version of each library in :data:`LIBRARIES` (None when absent)."""
    out: dict[str, str | None] = {}
    for name in LIBRARIES:
        try:
            out[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            out[name] = None

    out["opencv (cv2)"] = cv2.__version__
    return out


def _modules() -> list[ModuleType]:
    mods = []
    for pkg_name in _KERNEL_PACKAGES:
        pkg = importlib.import_module(pkg_name)
        mods.append(pkg)
        for info in pkgutil.walk_packages(pkg.__path__, prefix=pkg_name + "."):
            mods.append(importlib.import_module(info.name))
    return mods


def numba_kernels() -> dict[str, Any]:
    """Every numba dispatcher defined in the package, by ``module.function`` name."""

    out: dict[str, Any] = {}
    for mod in _modules():
        for name, obj in vars(mod).items():
            if isinstance(obj, CPUDispatcher) and obj.py_func.__module__ == mod.__name__:
                out[f"{mod.__name__}.{name}"] = obj
    return out


@dataclass(frozen=True)
class KernelCacheStatus:
    """How many kernels have an up-to-date compiled entry in numba's on-disk cache, and where."""

    n_kernels: int
    n_cached: int
    cache_dirs: tuple[str, ...]
    not_cached: tuple[str, ...]


def kernel_cache_status() -> KernelCacheStatus:
    """Look up each kernel's cache index (stale entries, from an edited source, count as missing)."""
    # helpers inlined into their callers are compiled (and cached) as part of those
    kernels = {k: d for k, d in numba_kernels().items() if d.targetoptions.get("inline") != "always"}
    cached, missing, dirs = 0, [], set()
    for name, disp in sorted(kernels.items()):
        cache = getattr(disp, "_cache", None)
        cache_file = getattr(cache, "_cache_file", None)
        if cache_file is None:  # cache=False
            missing.append(name)
            continue
        dirs.add(str(cache_file._cache_path))
        if os.path.exists(cache_file._index_path) and cache_file._load_index():
            cached += 1
        else:
            missing.append(name)
    return KernelCacheStatus(len(kernels), cached, tuple(sorted(dirs)), tuple(missing))


def describe() -> list[str]:
    """Lines for ``atsvo-info``: versions, then the kernel cache."""
    lines = [f"{'atsvo_ros':23s} {getattr(atsvo_ros, '__version__', '?')} ({os.path.dirname(atsvo_ros.__file__)})"]
    for name, ver in library_versions().items():
        lines.append(f"{name:23s} {ver or 'not installed'}")
    st = kernel_cache_status()
    where = os.path.commonpath(st.cache_dirs) if st.cache_dirs else "-"
    lines.append(f"numba kernels           {st.n_cached} of {st.n_kernels} compiled in the cache under {where} "
                 f"(NUMBA_CACHE_DIR={os.environ.get('NUMBA_CACHE_DIR', 'unset')})")
    if st.not_cached:
        lines.append("                        not cached yet (compiled on first use, seconds each): "
                     + ", ".join(n.rsplit(".", 1)[-1] for n in st.not_cached[:8])
                     + (" ..." if len(st.not_cached) > 8 else ""))
    return lines


__all__ = ["KernelCacheStatus", "describe", "kernel_cache_status", "library_versions", "numba_kernels"]
