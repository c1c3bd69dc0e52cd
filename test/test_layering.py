"""The package's layers, read from its imports (standard library ``ast`` only, nothing is imported).

Layers, lowest first; a module imports only from its own layer's package or from lower layers:
errors -> config -> core -> io -> eval | sim -> runtime -> tools | nodes -> bench. Inside core the
same holds for its concerns: the floor (geometry, camera, frame, imu, image, ...) -> events ->
mapping -> tracking -> odometry. There is no import cycle between modules, and imports inside
functions are kept for optional extras, for ROS inside ``nodes/`` and for the modules of ``nodes/`` (which
need rclpy) where a ROS-free module reaches them.
"""
from __future__ import annotations

import ast
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "atsvo_ros"

#: Top-level layers: a module may import its own package and any package of a lower rank.
LAYERS: dict[str, int] = {"errors": 0, "config": 1, "core": 2, "io": 3, "eval": 4, "sim": 4, "runtime": 5,
                          "tools": 6, "nodes": 6, "bench": 7}
#: Inside core: the floor is every module that is not one of these concerns.
CORE_LAYERS: dict[str, int] = {"events": 1, "mapping": 2, "tracking": 3, "odometry": 4}
#: What may be imported inside a function: optional extras (setup.py) and what only some machines have.
OPTIONAL = {"pyorbslam3", "aedat", "h5py", "evo", "dv_processing", "open3d", "apsw", "zstandard", "ament_index_python"}
#: ROS Python modules: imported inside functions of ``nodes/`` so the package imports without ROS.
ROS = {"rclpy", "builtin_interfaces", "std_msgs", "std_srvs", "sensor_msgs", "nav_msgs", "geometry_msgs",
       "diagnostic_msgs", "tf2_msgs", "tf2_ros", "event_camera_msgs", "dvs_msgs", "rosidl_runtime_py"}


@dataclass(frozen=True)
class Import:
    """One imported module (resolved to a module of the package where it is one) and where it is."""

    importer: str
    target: str
    line: int
    in_function: bool


def module_name(path: Path) -> str:
    rel = path.relative_to(PACKAGE.parent).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


MODULES: dict[str, Path] = {module_name(p): p for p in sorted(PACKAGE.rglob("*.py"))}


def _resolve(importer: str, is_package: bool, node: ast.ImportFrom) -> list[str]:
    """Modules named by ``from X import a, b``: ``X.a`` where that is a module of the package, else ``X``."""
    if node.level:
        base = importer.split(".")
        if not is_package:
            base = base[:-1]
        base = base[: len(base) - (node.level - 1)]
        pkg = ".".join(base + ([node.module] if node.module else []))
    else:
        pkg = node.module or ""
    out = []
    for alias in node.names:
        sub = f"{pkg}.{alias.name}"
        out.append(sub if sub in MODULES else pkg)
    return out


def imports(name: str) -> Iterator[Import]:
    path = MODULES[name]
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))

    def walk(node: ast.AST, in_function: bool) -> Iterator[Import]:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.Import):
                for alias in child.names:
                    yield Import(name, alias.name, child.lineno, in_function)
            elif isinstance(child, ast.ImportFrom):
                for target in _resolve(name, path.name == "__init__.py", child):
                    yield Import(name, target, child.lineno, in_function)
            else:
                inside = in_function or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda))
                yield from walk(child, inside)

    yield from walk(tree, False)


ALL_IMPORTS = [imp for name in MODULES for imp in imports(name)]


def rank(module: str) -> tuple[int, int] | None:
    """(layer, concern within core) of a package module; None outside the package."""
    parts = module.split(".")
    if parts[0] != "atsvo_ros" or len(parts) < 2:
        return None
    top = parts[1]
    if top not in LAYERS:
        return None
    inner = CORE_LAYERS.get(parts[2], 0) if top == "core" and len(parts) > 2 else 0
    return LAYERS[top], inner


def _layer(module: str) -> str:
    parts = module.split(".")
    return ".".join(parts[:3]) if parts[1] == "core" and len(parts) > 2 and parts[2] in CORE_LAYERS else \
        ".".join(parts[:2])


def test_every_top_level_module_has_a_layer():
    tops = {name.split(".")[1] for name in MODULES if name.count(".") >= 1}
    assert tops <= set(LAYERS), f"modules outside the known layers: {sorted(tops - set(LAYERS))}"


def test_no_module_imports_a_higher_layer():
    upward = []
    for imp in ALL_IMPORTS:
        src, dst = rank(imp.importer), rank(imp.target)
        if src is None or dst is None or _layer(imp.importer) == _layer(imp.target):
            continue
        same_top = imp.importer.split(".")[1] == imp.target.split(".")[1]
        if dst[0] > src[0] or (same_top and dst[1] > src[1]) or (dst[0] == src[0] and not same_top):
            upward.append(f"{MODULES[imp.importer].relative_to(PACKAGE.parent)}:{imp.line} imports {imp.target}")
    assert not upward, "imports against the layering:\n" + "\n".join(upward)


def _cycles(edges: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(edges.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(edges):
        if v not in index:
            visit(v)
    return out


def test_no_import_cycle():
    edges: dict[str, set[str]] = {name: set() for name in MODULES}
    for imp in ALL_IMPORTS:
        if imp.target in MODULES and imp.target != imp.importer:
            edges[imp.importer].add(imp.target)
    assert not _cycles(edges), f"import cycles: {_cycles(edges)}"


def test_function_level_imports_are_optional_extras_or_ros():
    bad = []
    for imp in ALL_IMPORTS:
        if not imp.in_function:
            continue
        root = imp.target.split(".")[0]
        in_nodes = imp.importer.startswith("atsvo_ros.nodes.")
        allowed = root in OPTIONAL or (root in ROS and in_nodes) or (imp.target.startswith("atsvo_ros.nodes.")
                                                                     and not in_nodes)
        if not allowed:
            bad.append(f"{MODULES[imp.importer].relative_to(PACKAGE.parent)}:{imp.line} imports {imp.target}")
    assert not bad, "imports inside functions (move them to the module top):\n" + "\n".join(bad)


def test_ros_is_imported_only_in_nodes():
    leaks = [f"{MODULES[i.importer].relative_to(PACKAGE.parent)}:{i.line} imports {i.target}" for i in ALL_IMPORTS
             if i.target.split(".")[0] in ROS and not i.importer.startswith("atsvo_ros.nodes")]
    assert not leaks, "ROS imports outside atsvo_ros/nodes:\n" + "\n".join(leaks)


@pytest.mark.parametrize("edges, expected", [
    ({"a": {"b"}, "b": {"c"}, "c": set()}, []),
    ({"a": {"b"}, "b": {"c"}, "c": {"a"}}, [["a", "b", "c"]]),
])
def test_the_cycle_finder_finds_cycles(edges, expected):
    assert _cycles(edges) == expected


def test_the_layer_check_sees_an_upward_import():
    assert rank("atsvo_ros.config") < rank("atsvo_ros.core.camera")
    assert rank("atsvo_ros.core.events.batch") < rank("atsvo_ros.core.mapping.map") < \
        rank("atsvo_ros.core.tracking.tracker") < rank("atsvo_ros.core.odometry.odometry")
    assert rank("atsvo_ros.core.geometry") < rank("atsvo_ros.core.events.batch")
    assert rank("atsvo_ros.runtime.runtime") < rank("atsvo_ros.tools.replay") < rank("atsvo_ros.bench.suite")
