"""The live view's tests: a real gyro_sim node over real DDS in its own ROS_DOMAIN_ID."""
import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
