"""Console script `gyro_sim_node`: the rclpy node `gyro_sim` and its main (SPEC.md, "ROS interface").

    gyro_sim_node --ros-args --params-file config/params.yaml -p duration:=20.0

`GyroSimNode` is a thin class (the ROS 2 examples' style): parameters, publishers, the command
subscription, the services; everything physical happens in the physics thread
(gyro_sim.ros.loop) over the core's Simulator. main() checks the command line before rclpy
starts (--help, misspelt parameters), starts rclpy, the node and its physics thread, spins the
executor in this thread (commands, ~/reset, ~/pause) until the bounded run ends or
SIGINT/SIGTERM (see `Shutdown`), then closes the log and prints a summary and where the log is.
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

try:  # rclpy from ROS 2 Jazzy (pip install 'gyro_sim[ros]'); --help works without it
    from rcl_interfaces.msg import ParameterDescriptor, ParameterType
    from rclpy.node import Node
    from std_msgs.msg import Float64MultiArray
    from std_srvs.srv import SetBool, Trigger

    ROS_IMPORT_ERROR = None
except ImportError as _exc:  # the class below is then never instantiated
    Node = object
    ROS_IMPORT_ERROR = _exc

from gyro_sim.simulator import Simulator  # noqa: E402
from gyro_sim.msgs.messages import decode_axis_moments  # noqa: E402
from gyro_sim.ros.loop import SimLoop  # noqa: E402
from gyro_sim.ros.outputs import Outputs  # noqa: E402
from gyro_sim.ros.params import PARAMETERS, ParameterError, validate  # noqa: E402

#: GIL switch interval (s) while the node runs: bounds how long the physics thread, woken at
#: its deadline, waits for the executor thread (Python's default is 5 ms)
SWITCH_INTERVAL = 5e-4
#: longest wait (s) for the physics thread to say how it is scheduled (it does so first thing)
STARTED_TIMEOUT = 1.0
#: longest wait of the executor (s): how soon a signal is acted on
SPIN_PERIOD = 0.1
#: the largest share of the interpreter the executor thread takes while callbacks keep coming:
#: after each callback it sleeps (1 / share - 1) times the time it took, leaving the
#: interpreter to the physics thread, so a flood of commands cannot starve the physics loop
EXECUTOR_SHARE = 0.2


def descriptor(p) -> ParameterDescriptor:
    """The descriptor of a parameter of gyro_sim.ros.params.PARAMETERS (read-only: set at start)."""
    kinds = {float: ParameterType.PARAMETER_DOUBLE, str: ParameterType.PARAMETER_STRING,
             bool: ParameterType.PARAMETER_BOOL}
    d = ParameterDescriptor(name=p.name, type=kinds[p.kind], description=p.description, read_only=True)
    if p.kind is float:
        # integers are accepted too (-p duration:=10): the type and range are checked by validate()
        d.dynamic_typing = True
        d.additional_constraints = f"a number in [{p.low:g}, {p.high:g}]"
    return d


def log_params(sim, cfg) -> dict:
    """The log's run parameters: the re-simulation contract of gyro_sim.log.record (one advance of
    1/physics_rate per step), plus the node's own parameters."""
    from gyro_sim.log.record import run_params

    own = {k: v for k, v in cfg.as_dict().items() if k not in ("publish_rate", "duration")}
    return run_params(sim, advance_dt=cfg.dt, publish_rate=cfg.publish_rate, source="gyro_sim_node",
                      duration=cfg.duration or None, **own)


def method_choice(sim, cfg) -> str:
    """What "fixed" steps with at the start and why, for the start line ("" for other methods)."""
    if cfg.integrator != "fixed":
        return ""
    from gyro_sim.integrators.fixed import fixed_step_method

    return fixed_step_method(sim, cfg.dt)[1]


def stiffness_note(sim, cfg) -> str:
    """A warning when the explicit fixed-step method runs a scene too stiff for its step
    (gyro_sim.integrators.fixed: h |lambda| at the initial state against RK4's limit)."""
    if cfg.integrator not in ("rk4", "lie4"):
        return ""
    from gyro_sim.integrators.fixed import fixed_step_choice

    c = fixed_step_choice(sim, cfg.dt)
    if c.method == "rk4" and c.substeps == 1:
        return ""
    return (f"the scene is stiff for {cfg.integrator} at physics_rate {cfg.physics_rate:g} Hz ({c.reason}); "
            f"it may stop with a simulation error or drift: raise physics_rate or try -p integrator:=fixed")


class GyroSimNode(Node):
    """The simulation node. Raises ParameterError (nothing created) on invalid parameters."""

    def __init__(self):
        super().__init__("gyro_sim")
        values, problems = {}, []
        for p in PARAMETERS:
            try:
                values[p.name] = self.declare_parameter(p.name, p.default, descriptor(p)).value
            except Exception as exc:  # noqa: BLE001 - rclpy's type and range exceptions
                problems.append(f"{p.name}: {exc}")
        if problems:
            raise ParameterError("\n".join(problems))
        self.config = cfg = validate(values)
        self.sim = Simulator(cfg.scene, integrator=cfg.integrator, rtol=cfg.rtol, atol=cfg.atol, step=cfg.dt,
                             backend=cfg.backend)
        self.recorder = None
        if cfg.record:
            from gyro_sim.ros.recorder import LiveRecorder

            self.recorder = LiveRecorder(cfg.record, scene=cfg.scene, params=log_params(self.sim, cfg),
                                         overwrite=cfg.overwrite)
        try:
            self.outputs = Outputs(self, self.sim, cfg, self.recorder)
            self.loop = SimLoop(self.sim, cfg, self.outputs)
        except BaseException:
            if self.recorder is not None:  # leave a readable (empty) log
                self.recorder.close()
            raise
        self.create_subscription(Float64MultiArray, "~/axis_moments", self.on_command, 10, raw=True)
        self.create_service(Trigger, "~/reset", self.on_reset)
        self.create_service(SetBool, "~/pause", self.on_pause)
        self.get_logger().info(
            f"scene '{cfg.scene.name}' ({cfg.scene_path}); axes {self.sim.axis_names}; "
            f"physics {cfg.physics_rate:g} Hz ({self.sim.integrator_name}"
            + (f" = {choice}" if (choice := method_choice(self.sim, cfg)) else "")
            + f", {self.sim.backend} dynamics), "
            f"publish {cfg.publish_rate:g} Hz, "
            f"real-time factor {cfg.real_time_factor:g}, {self.loop.per_chunk} steps per wake-up"
            + (f"; recording to {cfg.record}" if cfg.record else "")
        )
        self.stiffness_note = stiffness_note(self.sim, cfg)
        if self.stiffness_note:
            self.get_logger().warning(self.stiffness_note)

    def on_command(self, raw: bytes) -> None:
        """Bounded work: decode (no rclpy message objects), check, keep as the latest."""
        try:
            values = decode_axis_moments(raw)
        except ValueError:  # malformed bytes: refused like a NaN
            values = [float("nan")]
        reason = self.loop.submit_command(bytes(raw), values)
        if reason:
            self.get_logger().warning(
                f"command rejected ({reason}); axes: {self.sim.axis_names}; "
                f"{self.loop.counters.rejected} rejected so far", throttle_duration_sec=2.0)

    def on_reset(self, request, response):
        response.success, response.message = self.loop.request("reset")
        return response

    def on_pause(self, request, response):
        response.success, response.message = self.loop.request("pause", bool(request.data))
        return response

    def finish(self) -> dict:
        """Stop the loop, close the log; the run's statistics."""
        self.loop.stop()
        stats = self.loop.summary()
        if self.recorder is not None:
            self.recorder.close()
            stats.update(record=self.recorder.path, records_written=self.recorder.written,
                         recorder_max_backlog=self.recorder.max_backlog,
                         recorder_thread_cpu_s=self.recorder.thread_cpu, recorder_error=self.recorder.error,
                         recorder_sender_cpu_s=self.recorder.sender_cpu,
                         recorder_open_cpu_s=getattr(self.recorder, "open_cpu", 0.0))
        return stats


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
    from gyro_sim.ros.params import preflight

    # --help, misspelt parameters and the first numba compile, before rclpy starts
    code = preflight(sys.argv if argv is None else argv)
    if code is not None:
        return code
    if ROS_IMPORT_ERROR is not None:
        print(f"gyro_sim_node needs ROS 2 Jazzy's rclpy (pip install 'gyro_sim[ros]'): {ROS_IMPORT_ERROR}",
              file=sys.stderr)
        return 2
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions

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
                if node.loop.started.wait(STARTED_TIMEOUT):  # how the physics thread is scheduled
                    log = node.get_logger().info if node.loop.priority or not node.config.thread_priority \
                        or node.config.real_time_factor <= 0 else node.get_logger().warning
                    log(f"physics thread: {node.loop.scheduling}")
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


def _summary_line(stats: dict, cfg) -> None:
    print(
        f"gyro_sim_node: simulated {stats['node_time_s']:.3f} s in {stats['wall_s']:.3f} s wall "
        f"(real-time factor {stats['real_time_factor_achieved']:.3f}, target {cfg.real_time_factor:g}), "
        f"step time p50 {stats['step_time_p50_us']:.0f} us / p99 {stats['step_time_p99_us']:.0f} us, "
        f"{stats['deadline_misses']} deadline misses, CPU {100 * stats['cpu_share']:.0f} %"
    )


def _report(node, stats: dict, signal_name: str = "") -> None:
    cfg = node.config
    if signal_name:
        print(f"gyro_sim_node: {signal_name}: stopped at node time {stats['node_time_s']:.3f} s")
    if stats["wall_s"] == 0.0:
        print("gyro_sim_node: stopped during start-up, nothing simulated")
    else:
        _summary_line(stats, cfg)
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
