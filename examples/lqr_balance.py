"""Balance the reaction-wheel pendulum upright with an LQR designed from `sim.linearize()`.

A ROS 2 node to copy: it takes the pendulum's angle and the wheel's rate from /joint_states,
the pendulum's rate from the IMU's gyro (with its noise and bias), and publishes the wheel
torque on the simulator's ~/axis_moments once for each publication (the publish rate): when
the joint state and the IMU message of one stamp have both arrived, in either order.

    gyro_sim_node --ros-args -p scene:=rw_pendulum -p hold:=until_command   # shell 1: the simulator
    python examples/lqr_balance.py                                          # shell 2: this controller
    gyro-sim view --live                                                    # shell 3: watch it

`hold:=until_command` keeps the pendulum at its initial state until this controller's first
command, however late it starts. With `-p lockstep:=true` instead the simulator advances one
control period per command: the loop is closed exactly whatever the machine's load.

The design (`LqrBalancer.design`), in the model's own names (docs/linearization.md):

1. linearise the scene about upright at rest, x = [pendulum, pendulum_rate, wheel_spin];
2. discretise it with the input held over one controller period (`discrete(period)`, exact);
3. solve the discrete Riccati equation (scipy) for the gain K, u = -K x;
4. read x back from what is measured through the model's outputs C: the angle
   (pendulum.position), the IMU's gyro x (the pendulum's rate) and the wheel's rate relative
   to the body (wheel.velocity), x = C_m^-1 (z - z0).

The command is clipped to the wheel's max_torque. `LqrBalancer` knows nothing of ROS: the
lockstep test (test/examples/test_lqr_balance.py) drives the same object against a
Simulator in process.
"""
from __future__ import annotations

import copy
import sys

import numpy as np

SCENE = "rw_pendulum"
#: state weights: the inverse squares of what is acceptable (rad, rad/s, rad/s of the wheel)
STATE_SCALE = (0.05, 1.0, 300.0)


class LqrBalancer:
    """u = -K x for a scene's upright equilibrium, x from the measurements (module docstring)."""

    def __init__(self, K, measure_inverse, z0, wheel_index: int, n_axes: int, max_torque: float,
                 imu: str, closed_loop_radius: float):
        self.K, self.measure_inverse, self.z0 = K, measure_inverse, z0
        self.wheel_index, self.n_axes, self.max_torque = wheel_index, n_axes, max_torque
        self.imu = imu
        #: the spectral radius of Ad - Bd K (below 1: the loop is stable)
        self.closed_loop_radius = closed_loop_radius

    @classmethod
    def design(cls, scene=SCENE, period: float = 0.01, wheel: str = "wheel", hinge: str = "pendulum",
               state_scale=STATE_SCALE, torque_scale: float | None = None) -> LqrBalancer:
        from scipy.linalg import solve_discrete_are

        from gyro_sim import Simulator, load_scene

        scene = load_scene(scene)
        source = copy.deepcopy(scene.source)  # the same scene at the equilibrium: upright, at rest
        for b in source["bodies"]:
            if b["name"] == hinge:
                b["initial"] = {"angle": 0.0, "rate": 0.0}
            for r in b.get("rotors", []):
                if r["name"] == wheel:
                    r["spin"] = 0.0
        sim = Simulator(load_scene(source), integrator="rk4", backend="numpy")
        lin = sim.linearize()
        if not lin.is_equilibrium:
            raise ValueError(f"{scene.name}: upright at rest is not an equilibrium "
                             f"(max |f0| {lin.equilibrium_residual:g})")
        expected = (hinge, f"{hinge}_rate", f"{wheel}_spin")
        if lin.state_names != expected:
            raise ValueError(f"{scene.name}: the state is {lin.state_names}, this controller is for {expected}")
        iw = lin.input_names.index(wheel)
        wheel_rotor = next(r for b in scene.bodies for r in b.rotors if r.name == wheel)
        limit = wheel_rotor.limits.max_torque if wheel_rotor.limits and wheel_rotor.limits.max_torque else np.inf
        d = lin.discrete(period)
        Ad, Bd = d.Ad, d.Bd[:, [iw]]
        Q = np.diag(1.0 / np.asarray(state_scale, dtype=float) ** 2)
        R = np.array([[1.0 / (torque_scale or (limit if np.isfinite(limit) else 0.1)) ** 2]])
        P = solve_discrete_are(Ad, Bd, Q, R)
        K = np.linalg.solve(R + Bd.T @ P @ Bd, Bd.T @ P @ Ad)[0]
        radius = float(np.max(np.abs(np.linalg.eigvals(Ad - Bd @ K[None, :]))))
        imu = scene.imus[0].name
        rows = [lin.output_names.index(n) for n in (f"{hinge}.position", f"{imu}.gyro_x", f"{wheel}.velocity")]
        M = lin.C[rows]
        return cls(K, np.linalg.inv(M), lin.z0[rows], iw, len(lin.input_names), float(limit), imu, radius)

    def state(self, angle: float, gyro_x: float, wheel_rate: float) -> np.ndarray:
        """x = [pendulum, pendulum_rate, wheel_spin] from the measurements."""
        return self.measure_inverse @ (np.array([angle, gyro_x, wheel_rate]) - self.z0)

    def command(self, angle: float, gyro_x: float, wheel_rate: float) -> list[float]:
        """The axis moments (every axis, in command order): the wheel's -K x, clipped to its
        max_torque; the others zero."""
        u = float(np.clip(-self.K @ self.state(angle, gyro_x, wheel_rate), -self.max_torque, self.max_torque))
        out = [0.0] * self.n_axes
        out[self.wheel_index] = u
        return out


def main(argv=None) -> int:
    import argparse

    ap = argparse.ArgumentParser(description="LQR balancer for gyro_sim's reaction-wheel pendulum (ROS 2)")
    ap.add_argument("--scene", default=SCENE, help="the scene the simulator runs (default rw_pendulum)")
    ap.add_argument("--sim-node", default="/gyro_sim", help="the simulator node's name, with its namespace")
    ap.add_argument("--rate", type=float, default=100.0, help="the simulator's publish_rate (Hz): the control period")
    ap.add_argument("--duration", type=float, default=0.0, help="stop after this many wall seconds (0: Ctrl-C)")
    args = ap.parse_args(argv)
    import time

    import rclpy
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
    from sensor_msgs.msg import Imu, JointState
    from std_msgs.msg import Float64MultiArray

    ctrl = LqrBalancer.design(args.scene, period=1.0 / args.rate)
    rclpy.init()
    node = rclpy.create_node("lqr_balance")
    log = node.get_logger()
    log.info(f"K = {np.array2string(ctrl.K, precision=4)}, closed-loop spectral radius {ctrl.closed_loop_radius:.4f}")
    pub = node.create_publisher(Float64MultiArray, f"{args.sim_node}/axis_moments", 10)
    latest = {"joints": None, "imu": None}  # the last of each not yet answered
    handling = []  # wall seconds from a publication's receipt (its second message) to the command

    def stamp(msg) -> tuple[int, int]:
        return msg.header.stamp.sec, msg.header.stamp.nanosec

    def answer(kind: str, msg) -> None:
        t0 = time.perf_counter()
        latest[kind] = msg
        joints, imu = latest["joints"], latest["imu"]
        if joints is None or imu is None or stamp(joints) != stamp(imu):
            return  # one publication's two messages, answered once, whichever came first
        latest["joints"] = latest["imu"] = None
        i, j = joints.name.index("pendulum"), joints.name.index("wheel")
        out = Float64MultiArray()
        out.data = ctrl.command(joints.position[i], imu.angular_velocity.x, joints.velocity[j])
        pub.publish(out)
        handling.append(time.perf_counter() - t0)

    node.create_subscription(Imu, f"{args.sim_node}/imu/{ctrl.imu}", lambda m: answer("imu", m), 10)
    node.create_subscription(JointState, "/joint_states", lambda m: answer("joints", m), 10)
    executor = SingleThreadedExecutor()  # made once: rclpy.spin_once(node) adds and removes the node each call
    executor.add_node(node)
    end = time.monotonic() + args.duration if args.duration > 0 else None
    try:
        while rclpy.ok() and (end is None or time.monotonic() < end):
            executor.spin_once(timeout_sec=0.1)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if handling:
            h = np.array(handling) * 1e6
            print(f"lqr_balance: {len(h)} commands; receipt to publication p50 {np.percentile(h, 50):.0f} us, "
                  f"p99 {np.percentile(h, 99):.0f} us", flush=True)
        node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
