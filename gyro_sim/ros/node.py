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
import signal  # noqa: E402
import sys  # noqa: E402
import threading  # noqa: E402
import time  # noqa: E402

#: GIL switch interval (s) while the node runs: bounds how long the physics thread, woken at
#: its deadline, waits for the executor thread (Python's default is 5 ms)
SWITCH_INTERVAL = 5e-4
#: longest wait of the executor (s): how soon a signal is acted on
SPIN_PERIOD = 0.1
#: the largest share of the interpreter the executor thread takes while callbacks keep coming:
#: after each callback it sleeps (1 / share - 1) times the time it took, leaving the
#: interpreter to the physics thread, so a flood of commands cannot starve the physics loop
EXECUTOR_SHARE = 0.2


class Interrupted(BaseException):
    """A second SIGINT/SIGTERM during start-up: abandon it (what was opened is closed)."""


class Shutdown:
    """SIGINT and SIGTERM handling owned by the node, not by rclpy.

    rclpy's own handlers shut the context down from inside the signal, which races with the
    executor's wait ("failed to initialize wait set: the given context is not valid") and can
    leave the log unclosed. Here a signal only sets `requested`; the main loop sees it within
    one spin period, stops the physics thread, closes the log, and only then shuts rclpy down.
    During start-up (imports, the first numba compile, the warm-up) a first signal lets the
    start finish and then ends the run at once; a second one abandons the start.
    """

    def __init__(self):
        self.requested = threading.Event()
        self.starting = True
        self.signal_name = ""
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, self._handle)

    def _handle(self, signum, frame) -> None:
        if self.starting and self.requested.is_set():
            raise Interrupted()
        self.signal_name = signal.Signals(signum).name
        self.requested.set()


def main(argv=None) -> int:
    shutdown = Shutdown()
    try:
        return _main(argv, shutdown)
    except Interrupted:
        print(f"gyro_sim_node: {shutdown.signal_name} twice during start-up: not started", file=sys.stderr)
        return 0


def _main(argv, shutdown: Shutdown) -> int:
    from .params import preflight

    # --help, misspelt parameters and the first numba compile, before rclpy starts
    code = preflight(sys.argv if argv is None else argv)
    if code is not None:
        return code
    try:
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.signals import SignalHandlerOptions

        from .sim_node import GyroSimNode
    except ImportError as exc:
        print(f"gyro_sim_node needs ROS 2 Jazzy's rclpy (pip install 'gyro_sim[ros]'): {exc}", file=sys.stderr)
        return 2
    from .params import ParameterError

    try:
        rclpy.init(args=argv, signal_handler_options=SignalHandlerOptions.NO)
    except Exception as exc:  # noqa: BLE001 - rcl's argument errors (a missing --params-file ...)
        print(f"gyro_sim_node: bad arguments: {exc}".splitlines()[0], file=sys.stderr)
        return 2
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
        spin_error = None
        try:
            shutdown.starting = False
            if not shutdown.requested.is_set():
                node.loop.start()
            while not shutdown.requested.is_set() and not node.loop.finished.is_set():
                t0 = time.monotonic()
                executor.spin_once(timeout_sec=SPIN_PERIOD)
                busy = time.monotonic() - t0
                if busy < 0.5 * SPIN_PERIOD:  # it ran a callback
                    time.sleep(busy * (1.0 / EXECUTOR_SHARE - 1.0))
        except Exception as exc:  # noqa: BLE001 - the log is closed below whatever happened
            spin_error = f"{type(exc).__name__}: {exc}"
        stats = node.finish()
        _report(node, stats, shutdown.signal_name)
        if node.loop.crash:
            print(f"gyro_sim_node: the physics loop failed:\n{node.loop.crash}", file=sys.stderr)
            return 1
        if spin_error:
            print(f"gyro_sim_node: the executor failed: {spin_error}", file=sys.stderr)
            return 1
        if node.loop.failure is not None:
            print(f"gyro_sim_node: simulation error: {node.loop.failure}", file=sys.stderr)
            return 1
        return 0
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()


def _report(node, stats: dict, signal_name: str = "") -> None:
    cfg = node.config
    if signal_name:
        print(f"gyro_sim_node: {signal_name}: stopped at node time {stats['node_time_s']:.3f} s")
    print(
        f"gyro_sim_node: simulated {stats['node_time_s']:.3f} s in {stats['wall_s']:.3f} s wall "
        f"(real-time factor {stats['real_time_factor_achieved']:.3f}, target {cfg.real_time_factor:g}), "
        f"step time p50 {stats['step_time_p50_us']:.0f} us / p99 {stats['step_time_p99_us']:.0f} us, "
        f"{stats['deadline_misses']} deadline misses, CPU {100 * stats['cpu_share']:.0f} %"
    )
    if cfg.stats_file:
        try:
            with open(cfg.stats_file, "w") as f:
                json.dump(stats, f, indent=1, default=str)
        except OSError as exc:
            print(f"gyro_sim_node: stats_file {cfg.stats_file}: {exc.strerror or exc}", file=sys.stderr)
    if cfg.record:
        print(f"gyro_sim_node: log written: {cfg.record} ({stats['records_written']} records)")
        print(f"  view it:  rerun {cfg.record}")
        print(f"       or:  gyro-sim view {cfg.record}")
    sys.stdout.flush()


if __name__ == "__main__":
    sys.exit(main())
