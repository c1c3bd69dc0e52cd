"""Package-level checks: lint, ROS-free imports, ament layout."""
from __future__ import annotations

import configparser
import importlib
import pkgutil
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

import atsvo_ros

ROOT = Path(__file__).resolve().parents[1]


def test_ruff_is_clean():
    ruff = shutil.which("ruff")
    if ruff is None:
        pytest.skip("ruff not installed (pip install -e '.[test]')")
    out = subprocess.run([ruff, "check", "atsvo_ros", "test", "launch", "setup.py"], cwd=ROOT,
                         capture_output=True, text=True)
    assert out.returncode == 0, out.stdout + out.stderr


def test_every_module_outside_nodes_imports_without_ros():
    """Import each module in a fresh interpreter where rclpy & co. are made unimportable."""
    names = [m.name for m in pkgutil.walk_packages(atsvo_ros.__path__, "atsvo_ros.")
             if not m.name.startswith("atsvo_ros.nodes")]
    assert "atsvo_ros.core.geometry" in names
    blocker = (
        "import sys\n"
        "class _Block:\n"
        "    BLOCKED = ('rclpy', 'message_filters', 'sensor_msgs', 'nav_msgs', 'geometry_msgs', 'std_msgs',\n"
        "               'std_srvs', 'diagnostic_msgs', 'rcl_interfaces', 'tf2_ros', 'tf2_msgs',\n"
        "               'builtin_interfaces', 'event_camera_msgs', 'dvs_msgs')\n"
        "    def find_spec(self, name, path=None, target=None):\n"
        "        if name.split('.')[0] in self.BLOCKED:\n"
        "            raise ImportError(f'{name} blocked: core must not need ROS')\n"
        "        return None\n"
        "sys.meta_path.insert(0, _Block())\n"
        "import importlib\n"
        f"for n in {names!r}:\n"
        "    importlib.import_module(n)\n"
        "print('ok')\n")
    out = subprocess.run([sys.executable, "-c", blocker], capture_output=True, text=True, cwd=ROOT)
    assert out.returncode == 0 and "ok" in out.stdout, out.stderr


def test_nodes_import_only_with_rclpy():
    pytest.importorskip("rclpy", reason="rclpy is not installed (no ROS 2 on this machine)")
    for m in pkgutil.walk_packages(atsvo_ros.__path__, "atsvo_ros."):
        if m.name.startswith("atsvo_ros.nodes"):
            importlib.import_module(m.name)


def test_package_xml_is_format_3_with_runtime_dependencies():
    root = ET.parse(ROOT / "package.xml").getroot()
    assert root.get("format") == "3" and root.findtext("name") == "atsvo_ros"
    deps = {e.text for e in root.findall("exec_depend")}
    for dep in ("rclpy", "sensor_msgs", "nav_msgs", "geometry_msgs", "std_msgs", "std_srvs", "diagnostic_msgs",
                "tf2_ros", "tf2_msgs", "event_camera_msgs", "python3-numpy", "python3-opencv"):
        assert dep in deps
    assert "python3-pytest" in {e.text for e in root.findall("test_depend")}
    assert root.find("export/build_type").text == "ament_python"


def test_setup_cfg_installs_scripts_where_ros2_run_looks():
    cfg = configparser.ConfigParser()
    cfg.read(ROOT / "setup.cfg")
    assert cfg["develop"]["script_dir"] == "$base/lib/atsvo_ros"
    assert cfg["install"]["install_scripts"] == "$base/lib/atsvo_ros"
    assert (ROOT / "resource" / "atsvo_ros").is_file()


def test_ci_runs_the_readme_test_command_with_the_ros_tests_required():
    """.ci/run: the README's test command verbatim, after .ci/ros_env.sh, with missing ROS pieces made fatal."""
    readme = (ROOT / "README.md").read_text()
    ci = (ROOT / ".ci" / "run").read_text().splitlines()
    command = "pip install -e '.[test]' && python -m pytest -q"
    assert command in readme and ci[-1] == command
    assert ci.index("source .ci/ros_env.sh  # pip install -e '.[ros]', builds the messages (cached), exports the "
                    "DDS settings") < ci.index("export ATSVO_REQUIRE_ROS=1") < len(ci) - 1


def test_a_hung_test_fails_with_its_stack_and_the_run_goes_on(tmp_path):
    """setup.cfg's limits under xdist: the hung test's stack reaches the log, it fails, the next test still runs."""
    pytest.importorskip("pytest_timeout", reason="pytest-timeout is in the test extra")
    (tmp_path / "test_hang.py").write_text(
        "import threading\n\n"
        "def test_hangs():\n    threading.Event().wait()\n\n"
        "def test_after():\n    pass\n")
    cfg = configparser.ConfigParser()
    cfg.read(ROOT / "setup.cfg")
    opts = cfg["tool:pytest"]
    dump_s, kill_s = float(opts["faulthandler_timeout"]), float(opts["timeout"])
    assert 0 < dump_s < kill_s and opts["timeout_method"] == "thread"  # the stack is written before the end
    done = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-n", "1",
                           "-o", f"faulthandler_timeout={2 * dump_s / kill_s:.2f}", "-o", "timeout=2",
                           "-o", f"timeout_method={opts['timeout_method']}", str(tmp_path)],
                          capture_output=True, text=True, cwd=tmp_path, timeout=120)
    out = done.stdout + done.stderr
    assert done.returncode == 1, out
    assert "Timeout" in out and "in test_hangs" in out, out  # every thread's stack, the hung frame named
    assert "1 failed, 1 passed" in out, out
