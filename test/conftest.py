import os
import tempfile
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))
# rclpy writes a log file per process: keep them out of ~/.ros and out of the tree
os.environ.setdefault("ROS_LOG_DIR", os.path.join(tempfile.gettempdir(), "gyro_sim_test_ros_log"))
