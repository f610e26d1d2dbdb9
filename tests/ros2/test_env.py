"""Finding ROS 2 and loading it without LD_LIBRARY_PATH; the error without ROS 2; the run options."""
from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import pytest

from tests.ros2.conftest import REPO

pytestmark = pytest.mark.process


def python(*code: str, **env_changes: str | None) -> subprocess.CompletedProcess:
    """Runs the code parts (each dedented) in a fresh Python with the environment changes (None: unset)."""
    environ = {k: v for k, v in os.environ.items() if k not in env_changes}
    environ.update({k: v for k, v in env_changes.items() if v is not None})
    return subprocess.run([sys.executable, "-c", "\n".join(textwrap.dedent(part) for part in code)], capture_output=True, text=True, timeout=120, env=environ, cwd=REPO)


def test_rclpy_loads_and_publishes_without_ld_library_path_and_the_process_exits_cleanly():
    # The loader's LD_LIBRARY_PATH is unset at start (and the wheels' bootstrapper, if installed,
    # is told it already ran): EMOS preloads the libraries itself.
    done = python("""
        from emos.interop.ros2 import env
        install = env.ensure_loadable()
        import rclpy
        rclpy.init(domain_id=93)
        node = rclpy.create_node("probe")
        env.prepare_package("sensor_msgs")
        from sensor_msgs.msg import LaserScan
        node.create_publisher(LaserScan, "/probe", 10).publish(LaserScan(ranges=[1.0, 2.0]))
        node.destroy_node()
        rclpy.shutdown()
        print(install.describe())
    """, LD_LIBRARY_PATH=None, _ROS_WHEELS_BOOTSTRAP_COMPLETE="1", ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    assert done.returncode == 0, done.stderr
    line = done.stdout.strip()
    assert line.startswith("ROS 2 jazzy (rclpy 7.") and "rmw_fastrtps_cpp" in line and "from pip wheels in" in line


BLOCK_RCLPY = """
    import sys
    class NoRclpy:  # this Python as it would be without the ROS 2 wheels
        @staticmethod
        def find_spec(name, path=None, target=None):
            if name == "rclpy" or name.startswith("rclpy."):
                raise ModuleNotFoundError(f"No module named {name!r}")
            return None
    sys.meta_path.insert(0, NoRclpy)
"""


def test_without_ros2_the_error_says_what_to_install():
    done = python(BLOCK_RCLPY, """
        from emos.interop.ros2 import env
        print(env.describe())
        try:
            env.ensure_loadable()
        except env.Ros2Unavailable as exc:
            print("ERROR", exc)
        from emos.transport.select import use_ros2
        try:
            use_ros2(topics="all")
        except ImportError as exc:
            print("USE", exc)
        import os
        print("ENV", os.environ.get("EMOS_ROS2"))
    """, AMENT_PREFIX_PATH=None, ROS_DISTRO=None)
    assert done.returncode == 0, done.stderr
    out = done.stdout
    assert "ROS 2: not available (pip install 'emos[ros2]' for Jazzy)" in out
    assert "ERROR ROS 2 is not available to this Python" in out and "pip install 'emos[ros2]'" in out and "/opt/ros/jazzy/setup.bash" in out
    assert "USE ROS 2 is not available" in out
    assert "ENV None" in out  # nothing half-set


def test_use_ros2_checks_its_options_and_sets_the_run_options():
    done = python("""
        import os
        from emos.transport.select import use_ros2
        for bad in ({"topics": "/sc an"}, {"topics": 7}, {"domain_id": 300}, {"domain_id": True}):
            try:
                use_ros2(**bad)
            except (ValueError, TypeError) as exc:
                print("BAD", type(exc).__name__, exc)
        print("USED", use_ros2(topics="scan,/cmd_vel,/camera/*", domain_id=42))
        print("ENV", os.environ["EMOS_ROS2"], os.environ["EMOS_ROS2_TOPICS"], os.environ["EMOS_ROS2_DOMAIN_ID"])
        from emos.actors.ros2.component import config_from_environment
        cfg = config_from_environment()
        print("CFG", cfg.topics, cfg.domain_id)
    """)
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    bad = [line for line in lines if line.startswith("BAD")]
    assert len(bad) == 4
    assert "'/sc an' is invalid" in bad[0] and "TypeError" in bad[1] and "0..232" in bad[2] and "0..232" in bad[3]
    assert any(line.startswith("USED ROS 2 jazzy") for line in lines)
    assert "ENV 1 /scan,/cmd_vel,/camera/* 42" in lines
    assert "CFG ['/scan', '/cmd_vel', '/camera/*'] 42" in lines


def test_emos_run_ros2_without_ros2_fails_at_once_saying_what_to_install(tmp_path):
    recipe = tmp_path / "r.py"
    recipe.write_text("raise SystemExit('the recipe must not run')\n")
    done = python(BLOCK_RCLPY, f"""
        import sys
        from emos.tools.cli import main
        sys.argv = ["emos", "run", "--no-log", "--ros2", {str(recipe)!r}]
        sys.exit(main())
    """, AMENT_PREFIX_PATH=None, ROS_DISTRO=None)
    assert done.returncode == 2, (done.stdout, done.stderr)
    assert "emos run: --ros2: ROS 2 is not available" in done.stderr and "pip install 'emos[ros2]'" in done.stderr
    assert "the recipe must not run" not in done.stderr
