"""atsvo-info's environment report, and a guard: no numba kernel may need SciPy at run time."""
from __future__ import annotations

import ast
import inspect
import textwrap

from atsvo_ros.tools import info
from atsvo_ros.tools._environment import kernel_cache_status, library_versions, numba_kernels

#: numba implements these through SciPy's LAPACK/BLAS bindings; SciPy is not a runtime dependency.
_NEEDS_SCIPY = {"dot", "vdot", "matmul", "inner", "linalg"}


def _scipy_uses(fn) -> list[str]:
    tree = ast.parse(textwrap.dedent(inspect.getsource(fn)))
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.BinOp) and isinstance(node.op, ast.MatMult):
            found.append(f"line {node.lineno}: @")
        elif isinstance(node, ast.Attribute) and node.attr in _NEEDS_SCIPY:
            found.append(f"line {node.lineno}: .{node.attr}")
    return found


def test_no_kernel_uses_lapack_or_blas():
    kernels = numba_kernels()
    assert len(kernels) > 20  # the scan found the package's kernels
    offenders = {name: uses for name, k in kernels.items() if (uses := _scipy_uses(k.py_func))}
    assert not offenders, f"numba kernels calling SciPy-backed functions: {offenders}"


def test_info_lists_versions_and_kernel_cache(capsys):
    assert info.main([]) == 0
    out = capsys.readouterr().out
    versions = library_versions()
    assert versions["numpy"] and versions["numba"]
    for name in ("numpy", "numba", "opencv", "scipy", "numba kernels"):
        assert name in out
    st = kernel_cache_status()
    assert f"{st.n_cached} of {st.n_kernels}" in out
