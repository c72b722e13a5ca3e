import os
import tempfile
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))
# rclpy writes a log file per process: keep them out of ~/.ros and out of the tree
os.environ.setdefault("ROS_LOG_DIR", os.path.join(tempfile.gettempdir(), "gyro_sim_test_ros_log"))
# no kernel-cache fill left behind by a test's start: it would take the cores from the other
# tests (the tests of the fill opt in with "1" and a private NUMBA_CACHE_DIR)
os.environ["GYRO_SIM_BACKGROUND_FILL"] = "0"

#: what a run may leave in the clone: caches of Python, numba and pytest, build metadata, venvs
_TREE_OWN = {"__pycache__", ".git", ".pytest_cache", ".ci-venv", ".venv", "build", "dist"}


def _tree_files() -> dict[str, float]:
    """Every file of the clone outside caches and venvs, with its modification time."""
    out = {}
    for dirpath, dirnames, filenames in os.walk(ROOT):
        dirnames[:] = [d for d in dirnames if d not in _TREE_OWN and not d.endswith(".egg-info")]
        for f in filenames:
            p = os.path.join(dirpath, f)
            try:
                out[os.path.relpath(p, ROOT)] = os.stat(p).st_mtime
            except OSError:
                pass
    return out


def pytest_sessionstart(session):
    session.config._gyro_sim_tree = _tree_files()


def pytest_sessionfinish(session, exitstatus):
    """Tests run in their own temporary directories: a file the run created or changed in the
    clone fails the run, named."""
    before = getattr(session.config, "_gyro_sim_tree", None)
    if before is None:
        return
    after = _tree_files()
    touched = sorted(p for p, m in after.items() if before.get(p) != m)
    if touched:
        sys.stderr.write("\nthe tests wrote into the clone (they must use temporary directories): "
                         + ", ".join(touched[:20]) + "\n")
        session.exitstatus = 1
