"""Console script `gyro_sim_node`: the rclpy node `gyro_sim` (SPEC.md, "ROS interface").

    gyro_sim_node --ros-args --params-file config/params.yaml -p duration:=20.0

main() starts rclpy, the node (gyro_sim.ros.sim_node: parameters, publishers, the command
subscription, the services) and its physics thread (gyro_sim.ros.loop: steps, paces,
publishes), spins the executor in this thread (commands, ~/reset, ~/pause) until the bounded
run ends or SIGINT/SIGTERM, then closes the log and prints a summary and where the log is.
"""
from __future__ import annotations

import os

# One BLAS thread: the chain's matrices are small and a threaded BLAS fights the loop (cli.py).
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import json  # noqa: E402
import sys  # noqa: E402

#: GIL switch interval (s) while the node runs: bounds how long the physics thread, woken at
#: its deadline, waits for the executor thread (Python's default is 5 ms)
SWITCH_INTERVAL = 5e-4


def main(argv=None) -> int:
    try:
        import rclpy
        from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor

        from .sim_node import GyroSimNode
    except ImportError as exc:
        print(f"gyro_sim_node needs ROS 2 Jazzy's rclpy (pip install 'gyro_sim[ros]'): {exc}", file=sys.stderr)
        return 1
    from .params import ParameterError

    rclpy.init(args=argv)
    node = None
    try:
        try:
            node = GyroSimNode()
        except ParameterError as exc:
            print("gyro_sim_node: invalid parameters, nothing started:\n  " + str(exc).replace("\n", "\n  "),
                  file=sys.stderr)
            return 2
        sys.setswitchinterval(SWITCH_INTERVAL)
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        node.loop.start()
        try:
            while rclpy.ok() and not node.loop.finished.is_set():
                executor.spin_once(timeout_sec=0.1)
        except (KeyboardInterrupt, ExternalShutdownException):
            pass
        stats = node.finish()
        _report(node, stats)
        if node.loop.crash:
            print(f"gyro_sim_node: the physics loop failed:\n{node.loop.crash}", file=sys.stderr)
            return 1
        return 0
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()


def _report(node, stats: dict) -> None:
    cfg = node.config
    print(
        f"gyro_sim_node: simulated {stats['node_time_s']:.3f} s in {stats['wall_s']:.3f} s wall "
        f"(real-time factor {stats['real_time_factor_achieved']:.3f}, target {cfg.real_time_factor:g}), "
        f"step time p50 {stats['step_time_p50_us']:.0f} us / p99 {stats['step_time_p99_us']:.0f} us, "
        f"{stats['deadline_misses']} deadline misses, CPU {100 * stats['cpu_share']:.0f} %"
    )
    if cfg.stats_file:
        with open(cfg.stats_file, "w") as f:
            json.dump(stats, f, indent=1, default=str)
    if cfg.record:
        print(f"gyro_sim_node: log written: {cfg.record} ({stats['records_written']} records)")
        print(f"  view it:  rerun {cfg.record}")
        print(f"       or:  gyro-sim view {cfg.record}")
    sys.stdout.flush()


if __name__ == "__main__":
    sys.exit(main())
