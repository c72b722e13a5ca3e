"""The rclpy node `gyro_sim`: parameters, publishers, the command subscription, the services.

A thin class (the ROS 2 examples' style): everything physical happens in the physics thread
(gyro_sim.ros.loop) over the core's Simulator; this class wires it to ROS.
"""
from __future__ import annotations

from rcl_interfaces.msg import ParameterDescriptor, ParameterType
from rclpy.node import Node
from std_msgs.msg import Float64MultiArray
from std_srvs.srv import SetBool, Trigger

from ..core.simulator import Simulator
from ..io.messages import decode_axis_moments
from .loop import SimLoop
from .outputs import Outputs
from .params import PARAMETERS, ParameterError, validate


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
    """The log's run parameters: the re-simulation contract of gyro_sim.io.record (one advance of
    1/physics_rate per step), plus the node's own parameters."""
    from ..io.record import run_params

    own = {k: v for k, v in cfg.as_dict().items() if k not in ("publish_rate", "duration")}
    return run_params(sim, advance_dt=cfg.dt, publish_rate=cfg.publish_rate, source="gyro_sim_node",
                      duration=cfg.duration or None, **own)


def recorder_options(cfg) -> dict:
    """LogWriter options from the parameters (overwrite:=true lets record replace a file)."""
    return {"overwrite": True} if getattr(cfg, "overwrite", False) else {}


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
            from .recorder import LiveRecorder

            self.recorder = LiveRecorder(cfg.record, scene=cfg.scene, params=log_params(self.sim, cfg),
                                         **recorder_options(cfg))
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
            f"physics {cfg.physics_rate:g} Hz ({self.sim.integrator_name}, {self.sim.backend} dynamics), "
            f"publish {cfg.publish_rate:g} Hz, "
            f"real-time factor {cfg.real_time_factor:g}, {self.loop.per_chunk} steps per wake-up"
            + (f"; recording to {cfg.record}" if cfg.record else "")
        )

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
                         recorder_thread_cpu_s=self.recorder.thread_cpu, recorder_error=self.recorder.error)
        return stats
