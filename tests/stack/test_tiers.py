"""The test tiers: started without scripts/test.sh, pytest still runs the ROS tests (conftest sets
up the stack environment itself), and says why when it cannot, instead of skipping them."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
#: A ROS test that only passes where the ament index finds the installed packages.
ROS_TEST = ("tests/stack/test_layout.py::"
            "test_config_files_are_installed_to_share_and_found_through_the_ament_index")


def pytest_outside_the_stack_environment(**extra: str) -> subprocess.CompletedProcess:
    """``python -m pytest ROS_TEST`` from a shell that never ran scripts/test.sh."""
    env = {"PATH": "/usr/bin:/bin", "HOME": str(Path.home()), **extra}
    return subprocess.run([sys.executable, "-m", "pytest", ROS_TEST, "-p", "no:cacheprovider",
                           "-q", "-rA"], cwd=ROOT, env=env, capture_output=True, text=True,
                          timeout=120)


def test_ros_tests_run_outside_scripts_test_sh():
    result = pytest_outside_the_stack_environment()
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-2000:]
    assert "1 passed" in result.stdout


def test_ros_tests_fail_with_the_reason_when_there_is_no_workspace(tmp_path):
    result = pytest_outside_the_stack_environment(QG_ROS_INSTALL=str(tmp_path / "nowhere"))
    assert result.returncode == 1, result.stdout[-3000:]
    assert "1 error" in result.stdout and "skipped" not in result.stdout \
        and "xfail" not in result.stdout
    assert f"needs the stack environment: FileNotFoundError: {tmp_path / 'nowhere'} has no " \
           "setup.bash" in result.stdout
