"""The Simulator: the stable Python API (README, "Python API") over model, dynamics and integrators."""
from __future__ import annotations

import math
import os
from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np

from gyro_sim.errors import GyroSimError
from gyro_sim.dynamics import invariants as inv
from gyro_sim.dynamics.model import compile_model, initial_state
from gyro_sim.scene.records import Scene
from gyro_sim.snapshot import Scatter, Snapshot


#: the integrators that take a stateful model (speed-dependent actuator terms: the spins and
#: works are plain states; "fixed" then takes gauss4 as its implicit rung); the others
#: integrate a structure of their own (canonical momenta, Lie groups)
STATEFUL_INTEGRATORS = ("auto", "dop853", "fixed", "gauss4", "radau", "rk4")


class SimulationError(GyroSimError, RuntimeError):
    """The integration failed (non-finite state, step-size collapse); the state is kept."""


@dataclass(frozen=True)
class JointStates:
    """As sensor_msgs/JointState: parallel lists."""

    name: list[str]
    position: list[float]
    velocity: list[float]
    effort: list[float]


@dataclass(frozen=True)
class Wrench:
    """Reaction of body k-1 (or the base) on body k at O^k: R^k (eq 40), L^k (eq 48)."""

    joint: str
    frame: str  # the frame of the components: the body's own frame
    force: np.ndarray  # (3,)
    moment: np.ndarray  # (3,)


@dataclass(frozen=True)
class BodyState:
    name: str
    position: np.ndarray  # O^k, world
    rotation: np.ndarray  # world_R_body (3, 3)
    quaternion: np.ndarray  # (w, x, y, z), world from body
    angular_velocity: np.ndarray  # w^k, world
    velocity: np.ndarray  # velocity of O^k, world


class Simulator:
    """Simulate a scene. See the README, "Python API".

    Parameters
    ----------
    scene : Scene, path or mapping
    integrator : name of the integration method (see `gyro_sim.integrators.INTEGRATORS`);
        the default "auto" is dop853 that switches to radau when the scene turns out stiff
    rtol, atol : tolerances of adaptive methods
    step : step of fixed-step methods (s)
    backend : "auto" (numba-compiled O(n) articulated-body recursion when numba is there, else
        numpy), "numba", or "numpy" (the vectorised reference of gyro_sim.dynamics.reference)
    """

    def __init__(
        self,
        scene: Scene | str | os.PathLike | Mapping,
        integrator: str = "auto",
        rtol: float = 1e-10,
        atol: float = 1e-12,
        step: float = 1e-3,
        backend: str = "auto",
    ):
        if not isinstance(scene, Scene):
            from gyro_sim.scene.load import load_scene

            scene = load_scene(scene)
        self.scene = scene
        self.model = compile_model(scene)
        from gyro_sim.dynamics.system import make_system

        self.system = make_system(self.model, backend)  # numba-compiled, or the numpy reference
        self.integrator_name = integrator
        from gyro_sim.integrators import make_integrator

        self._integrator_options = {"rtol": rtol, "atol": atol, "step": step}
        self.integrator = make_integrator(integrator, self.system, **self._integrator_options)
        from gyro_sim.analytic.lagrange import LagrangeChain

        self._lagrange = LagrangeChain.from_scene(scene)  # None unless a chain of Lagrange gyroscopes
        m = self.model
        # rotors of each body, in scene order: (torque rotor indices, speed rotor indices)
        self._rotors_of = [
            (np.flatnonzero(m.torque_body == k).tolist(), np.flatnonzero(m.speed_body == k).tolist())
            for k in range(m.n)
        ]
        # index in the state vector of the angle each actuated axis drives (hinge phi or rotor
        # kappa): the work of a held moment over an advance is moment * change of that angle
        i_phi = np.arange(m.size)[m.i_phi]
        i_kappa = np.arange(m.size)[m.i_kappa]
        self._axis_angle = np.array([i_phi[h] if h >= 0 else i_kappa[r]
                                     for h, r in zip(m.axis_hinge, m.axis_rotor)], dtype=int)
        self._conserved = inv.conserved(m)
        self._balanced = inv.balanced_energy(m)  # whose balance E - E0 - W the motion keeps
        self._axis_max_torque = self._axis_limits()
        if (m.servo is not None or m.stateful) and integrator not in STATEFUL_INTEGRATORS:
            from gyro_sim.dynamics.actuators import ActuatorError

            if m.servo is not None:
                raise ActuatorError(f"integrator {integrator!r} does not take servos (state-dependent "
                                    f"hinge moments); use one of {', '.join(STATEFUL_INTEGRATORS)}")
            raise ActuatorError(f"{m.actuators.terms[0]}: integrator {integrator!r} does not take speed-dependent "
                             f"actuator terms (friction, max_speed); use one of {', '.join(STATEFUL_INTEGRATORS)}")
        self._joint_layout()
        self._coulomb = None  # exact Coulomb friction of hinges and rotors (gyro_sim.integrators.coulomb.driver)
        if m.actuators is not None and m.actuators.exact:
            from gyro_sim.integrators.coulomb.driver import CoulombStepping

            self._coulomb = CoulombStepping(m, self.system, self.integrator, step)
        self._watched = self._watched_energy()
        self._bind_backend()
        self._imus = None  # the IMUs (gyro_sim.dynamics.imu.ImuSet), when the scene has some
        if scene.imus:
            from gyro_sim.dynamics.imu import DEFAULT_IMU_RATE, ImuSet

            self._imus = ImuSet(scene, {b.name: k for k, b in enumerate(scene.bodies)}, scene.gravity,
                                DEFAULT_IMU_RATE)
        self.reset()
        if self._coulomb is not None:
            self._coulomb.warm_up(self._t, self._y, *self._inputs(), self._p)

    def _bind_backend(self) -> None:
        """The outputs of the system's backend, and the "fixed" integrator's energy watchdog."""
        from gyro_sim.dynamics.backends import CompiledOutputs, NumpyOutputs

        # every output of a state from one compiled call on the numba backend (a stateful model's
        # applied torques too), from the numpy reference on the numpy backend; its inputs: the
        # commands, and the exact friction's mean moment over the last step
        outputs = CompiledOutputs if self.system.backend == "numba" else NumpyOutputs
        self._outputs = outputs(self.model, self.system, self._joint_index,
                                self._inputs if self._coulomb is None else self._inputs_with_friction)
        self._watch_last = None
        if self._watched is not None and getattr(self.integrator, "monitor", False) is None:
            self.integrator.monitor = self._energy_error  # "fixed": its energy watchdog

    def switch_backend(self, backend: str) -> None:
        """From the next `advance` on, step on `backend` ("numba" or "numpy"; make_system's
        names), the state, time, commands, work and drift reference kept: a new system of that
        backend, and a new integrator of the same method and options over it, reset (as after a
        `reset`: a "fixed" integrator chooses its method afresh at the next step). The same call
        at the same step gives the same run: the node records it, re-simulation repeats it
        (gyro_sim.log.resim). On "numba" its kernels are compiled or loaded here when this
        process has not run them yet."""
        from gyro_sim.dynamics.system import make_system
        from gyro_sim.integrators import make_integrator

        self.system = make_system(self.model, backend)
        self.integrator = make_integrator(self.integrator_name, self.system, **self._integrator_options)
        if self._coulomb is not None:
            self._coulomb.bind(self.system, self.integrator)
        self._bind_backend()
        self._outputs.moved(self._t, self._y, self._p, self._moments)

    def _axis_limits(self) -> np.ndarray | None:
        """max_torque of every actuated axis (na,), +inf where none; None when no axis has one."""
        act, m = self.model.actuators, self.model
        if act is None or not (act.rotor.saturates or act.hinge.saturates):
            return None
        return np.array([act.hinge.max_torque[h] if h >= 0 else act.rotor.max_torque[r]
                         for h, r in zip(m.axis_hinge, m.axis_rotor)])

    def _inputs_moments(self) -> np.ndarray:
        """The commanded axis moments saturated to their max_torque (na,)."""
        if self._axis_max_torque is None:
            return self._moments
        return np.clip(self._moments, -self._axis_max_torque, self._axis_max_torque)

    def _watched_energy(self) -> int | None:
        """The index in the compiled invariants of the energy whose balance the exact motion keeps
        ("energy", or "jacobi" with speed rotors: gyro_sim.dynamics.invariants.balanced_energy),
        None when none is kept (a moving base). On the numpy backend the same numbers come from the numpy
        invariants (NumpyOutputs.energies)."""
        from gyro_sim.dynamics import outputs as fast_outputs

        if self._balanced == "energy":
            return fast_outputs.INV_ENERGY
        return fast_outputs.INV_JACOBI if self._balanced == "jacobi" else None

    def _energy_error(self, t0: float, y0: np.ndarray, t1: float, y1: np.ndarray) -> float:
        """How far an integrator's call from (t0, y0) to (t1, y1) breaks the energy balance,
        relative to the kinetic energy: (E1 - E0 - W) / max(T0, T1), W the work of the held
        moments (exact under the zero-order hold; with speed rotors the Jacobi integral's
        balance, which the commands' work moves as it moves the energy); 0 where no balance
        holds (a moving base). The kinetic energy, not T + |V|: the potential's zero is
        arbitrary, and a step that does not resolve the motion errs in proportion to the motion.
        Called by the "fixed" integrator after each call."""
        if self._watched is None:
            return 0.0
        if self.model.stateful:  # the applied torques' work is a state: the motors', the servos', friction's
            w = self.model.i_work
            work = float(np.sum(y1[w] - y0[w]))
        else:
            i = self._axis_angle
            work = float(self._inputs_moments() @ (y1[i] - y0[i])) if len(i) and np.any(self._moments) else 0.0
            if self._coulomb is not None and np.any(self._coulomb.torque):  # exact friction's held moments
                work += self._coulomb.held(y0, y1)
        from gyro_sim.dynamics.outputs import INV_KINETIC

        last = self._watch_last  # the previous call's end is usually this one's start
        v0 = last[2] if last is not None and last[0] == t0 and np.array_equal(last[1], y0) \
            else self._outputs.energies(t0, y0)
        v1 = self._outputs.energies(t1, y1)
        self._watch_last = (t1, y1.copy(), v1)
        scale = max(v0[INV_KINETIC], v1[INV_KINETIC], 1e-300)
        return float((v1[self._watched] - v0[self._watched] - work) / scale)

    def _joint_layout(self) -> None:
        """The joint-state entries in order (docs/scene-format.md, "Joint states"): their names, and where each entry's
        position, velocity and effort come from (gyro_sim.dynamics.backends.joint_sources): the Euler
        angles of every body (3 n, zero effort), the hinges, the torque rotors, the speed rotors."""
        m = self.model
        n, nh, nt = m.n, len(m.hinge_bodies), len(m.torque_body)
        names, idx = [], []
        ih = 0
        for k, body in enumerate(m.names):
            if m.is_hinge[k]:
                names.append(body)
                idx.append(3 * n + ih)
                ih += 1
            else:
                names += [f"{body}_psi", f"{body}_theta", f"{body}_phi"]
                idx += [3 * k, 3 * k + 1, 3 * k + 2]
            for i in self._rotors_of[k][0]:
                names.append(m.torque_names[i])
                idx.append(3 * n + nh + i)
            for i in self._rotors_of[k][1]:
                names.append(m.speed_names[i])
                idx.append(3 * n + nh + nt + i)
        self._joint_names = names
        self._joint_index = np.array(idx, dtype=np.intp)
        #: the snapshot's names (joint states, axes, bodies): one tuple each for the simulator's life
        self._snapshot_names = (tuple(names), tuple(m.axis_names), tuple(m.names))

    @property
    def joint_names(self) -> tuple[str, ...]:
        """The names of the joint-state entries in order (docs/scene-format.md), those of every snapshot: the
        same tuple for the simulator's life."""
        return self._snapshot_names[0]

    # --- state -----------------------------------------------------------------------------
    def reset(self) -> None:
        """Back to the scene's initial state, axis moments zero, the servos' controls their
        initial `control`."""
        m = self.model
        self._t = 0.0
        self._y = initial_state(m)
        self._p = m.torque_p0.copy() if len(m.torque_body) else None
        self._moments = np.zeros(len(m.axis_names))
        self._controls = self.initial_controls
        self._saturated = 0  # commanded values clipped to their max_torque since the reset
        self._outputs.moved(self._t, self._y, self._p, self._moments)
        self._watch_last = None
        self.integrator.reset()
        if self._coulomb is not None:
            self._coulomb.reset()
        self._work = 0.0
        self._reference = None  # invariants of the reset state (taken by the first advance or snapshot)
        if self._imus is not None:
            self._imus.reset()

    @property
    def time(self) -> float:
        return self._t

    @property
    def state(self) -> np.ndarray:
        """A copy of the state vector (layout: gyro_sim.dynamics.model)."""
        return self._y.copy()

    @property
    def axis_names(self) -> list[str]:
        return list(self.model.axis_names)

    @property
    def axis_moments(self) -> np.ndarray:
        """The commanded axis moments now in force (a copy)."""
        return self._moments.copy()

    @property
    def error_estimate(self) -> float | None:
        """The integrator's weighted local error norm of its last accepted step (adaptive
        methods; None for fixed-step ones): below 1 means within rtol/atol."""
        return self.integrator.error_estimate

    def set_axis_moments(self, values: Sequence[float] | Mapping[str, float]) -> None:
        """Commanded axis moments (N m), held until changed: an array in `axis_names` order, or a
        mapping from axis names to moments, the others kept (an imported model's commands in
        another order than the chain's, MuJoCo's actuator order, set by name)."""
        names = self.model.axis_names
        if isinstance(values, Mapping):
            v = self._moments.copy()
            for name, value in values.items():
                if name not in names:
                    raise ValueError(f"no commanded axis named {name!r} (axes: {list(names)})")
                v[list(names).index(name)] = float(value)
        else:
            v = np.asarray(values, dtype=float).ravel()
        if v.shape != (len(names),):
            raise ValueError(f"expected {len(names)} axis moments {self.axis_names}, got {v.size}")
        if not np.all(np.isfinite(v)):
            raise ValueError("axis moments must be finite")
        if self._axis_max_torque is not None:
            self._saturated += int(np.count_nonzero(np.abs(v) > self._axis_max_torque))
        self._moments = v.copy()
        self._outputs.commanded(self._moments)  # reactions and efforts depend on the commands

    @property
    def control_names(self) -> tuple[str, ...]:
        """The servos' controls, in the order of `controls` (the actuators' names of an imported
        model; a scene's `servo.name`, by default its hinge's)."""
        return self.model.servo_names

    @property
    def initial_controls(self) -> np.ndarray:
        """The servos' controls from the start and after each reset, in `control_names` order:
        each servo's `control` (an imported model's keyframe `ctrl`; default 0); a copy."""
        return self.model.initial_controls

    @property
    def controls(self) -> np.ndarray:
        """The servos' controls now in force, as set (before their ctrl_range clip; a copy)."""
        return self._controls.copy()

    def set_controls(self, values: Sequence[float] | Mapping[str, float]) -> None:
        """Set the servos' controls, held until changed (zero-order hold; their initial
        `control`, `initial_controls`, after a reset):
        an array in `control_names` order, or a mapping from control (actuator) or joint names
        to values, the others kept. Each servo clips its control to its ctrl_range."""
        m = self.model
        if isinstance(values, Mapping):
            v = self._controls.copy()
            joints = self._servo_joints()
            for name, value in values.items():
                i = m.servo_names.index(name) if name in m.servo_names else joints.get(name)
                if i is None:
                    raise ValueError(f"no servo named {name!r} (servos: {list(m.servo_names)})")
                v[i] = float(value)
        else:
            v = np.asarray(values, dtype=float).ravel()
            if v.shape != (len(m.servo_names),):
                raise ValueError(f"expected {len(m.servo_names)} controls {list(m.servo_names)}, got {v.size}")
        if not np.all(np.isfinite(v)):
            raise ValueError("controls must be finite")
        self._controls = v.copy()
        self._moments = self._moments.copy()  # a new object: the outputs see new commands
        self._outputs.commanded(self._moments)

    def _servo_joints(self) -> dict[str, int]:
        """Each servo's joint (its hinge body's name) -> its index in `control_names`."""
        return {name: i for i, (name, _) in enumerate(self.model.servo_joints)}

    def joint_command_controls(self, names: Sequence[str], position: Sequence[float], velocity: Sequence[float],
                               effort: Sequence[float], base: np.ndarray | None = None) -> np.ndarray:
        """The controls (in `control_names` order) after a joint command as the topic-based
        ros2_control hardware interfaces send it (sensor_msgs/JointState by joint name): each
        named joint's servo takes its position (a position servo), velocity (a velocity servo)
        or effort (a motor) entry; the other servos keep theirs from `base` (default: the
        controls now). ValueError naming the problem: a name that is no servo's joint, or given
        twice, an array neither empty nor one per name, a non-finite value in any array, the
        entry a servo takes missing."""
        m = self.model
        arrays = {"position": np.asarray(position, dtype=float), "velocity": np.asarray(velocity, dtype=float),
                  "effort": np.asarray(effort, dtype=float)}
        for kind, a in arrays.items():
            if a.size not in (0, len(names)):
                raise ValueError(f"{kind}: {a.size} values for {len(names)} names (empty or one per name)")
            if not np.all(np.isfinite(a)):
                raise ValueError(f"{kind}: holds NaN or inf")
        servo_of = self._servo_joints()
        out = (self._controls if base is None else np.asarray(base, dtype=float)).copy()
        seen = set()
        for i, name in enumerate(names):
            if name not in servo_of:
                raise ValueError(f"joint {name!r}: no servo drives it (servo joints: {list(servo_of)})")
            if name in seen:
                raise ValueError(f"joint {name!r}: given twice")
            seen.add(name)
            kind = m.servo_joints[servo_of[name]][1].command
            if arrays[kind].size == 0:
                raise ValueError(f"joint {name!r}: its servo takes a {kind}, the command has none")
            out[servo_of[name]] = arrays[kind][i]
        return out

    def _inputs(self):
        """The held inputs (hinge moments (nh,), rotor torques (nt,), or None) from the commanded
        axis moments, saturated to the axes' max_torque, and the servos' drives (their hinges'
        entries: gyro_sim.dynamics.reference.servo_drives)."""
        m, v = self.model, self._inputs_moments()
        hinge_tau = L_rotor = None
        if m.servo is not None:
            from gyro_sim.dynamics.reference import servo_drives

            hinge_tau = np.zeros(len(m.hinge_bodies))
            hinge_tau[m.servo_hinge] = servo_drives(m, self._controls)
        if len(v):
            if hinge_tau is None:
                hinge_tau = np.zeros(len(m.hinge_bodies))
            sel = m.axis_hinge >= 0
            hinge_tau[m.axis_hinge[sel]] = v[sel]
            if len(m.torque_body):
                L_rotor = np.zeros(len(m.torque_body))
                sel = m.axis_rotor >= 0
                L_rotor[m.axis_rotor[sel]] = v[sel]
        return hinge_tau, L_rotor

    def _inputs_with_friction(self):
        """The held inputs of the commands (`_inputs`) with the exact Coulomb friction of hinges and rotors
        moments of the last step added (their mean over it): what the outputs (effort,
        accelerations, reactions, IMUs) see."""
        hinge_tau, L_rotor = self._inputs()
        m, c = self.model, self._coulomb
        hinge_tau = np.zeros(len(m.hinge_bodies)) if hinge_tau is None else hinge_tau.copy()
        hinge_tau[c.axes] += c.applied[:c.nh]
        if len(c.rotors):
            L_rotor = np.zeros(len(m.torque_body)) if L_rotor is None else L_rotor.copy()
            L_rotor[c.rotors] += c.applied[c.nh:]
        return hinge_tau, L_rotor

    def held_rhs(self):
        """The right-hand side f(t, y) -> (size,) of the chain with the inputs now in force held,
        as `advance` holds them: for an analysis at the current state (the method choice of the
        "fixed" integrator). Its calls use the output workspace: outputs are computed afresh after."""
        hinge_tau, L_rotor = self._inputs()
        self.system.hold(self._t, self._p, hinge_tau, L_rotor)
        self._outputs.stale()  # the rhs's calls write the workspaces the outputs read
        return self.system.rhs

    def advance(self, dt: float) -> None:
        """Integrate `dt` seconds of simulated time with the commands held (zero-order hold)."""
        if not (dt > 0 and math.isfinite(dt)):
            raise ValueError(f"dt must be a positive finite number, got {dt!r}")
        if self._reference is None:  # the drifts' reference is the reset state: keep it before moving
            self._reference = self.invariants()
        self._outputs.stale()  # the integrator's evaluations and the energy watchdog's overwrite its workspaces
        hinge_tau, L_rotor = self._inputs()
        self.system.hold(self._t, self._p, hinge_tau, L_rotor)
        try:
            if self._coulomb is not None:  # the smooth motion between the friction's stick/slip steps
                y = self._coulomb.advance(self._t, self._y, self._t + dt, hinge_tau, L_rotor)
            else:
                y = self.integrator.advance(self._t, self._y, self._t + dt)
        except (FloatingPointError, np.linalg.LinAlgError, ArithmeticError) as exc:
            self.integrator.reset()  # its step-size memory is meaningless after a failure
            raise SimulationError(f"t = {self._t:.6g} s: {exc}; state kept at t = {self._t:.6g} s") from exc
        if not np.all(np.isfinite(y)):
            self.integrator.reset()
            raise SimulationError(f"t = {self._t:.6g} s: the state became non-finite; "
                                  f"state kept at t = {self._t:.6g} s")
        if self.model.stateful:  # the works are states, integrated with the motion
            self._work = float(y[self.model.i_work][0]) - (0.0 if self._coulomb is None else self._coulomb.held_work)
        elif len(self._axis_angle) and np.any(self._moments):
            i = self._axis_angle
            self._work += float(self._inputs_moments() @ (y[i] - self._y[i]))
        self._p = self.system.spins(self._t + dt, y)
        self._t += dt
        self._y = y
        # with exact friction a new moments object: the outputs hold the friction's new moments
        self._outputs.moved(self._t, self._y, self._p, self._moments if self._coulomb is None else self._moments.copy())

    # --- outputs (computed on request only) ------------------------------------------------
    # Every output comes from the backend the Simulator holds (gyro_sim.dynamics.backends): on
    # the numba backend one compiled call, the snapshot's and these alike (a log re-simulates bit
    # for bit against any of them); the numpy reference is what the compiled outputs are tested
    # against.
    def body_states(self) -> list[BodyState]:
        """Pose and velocity of every body."""
        O, R, q, w, vO = self._outputs.bodies()
        return [BodyState(name, O[k], R[k], q[k], w[k], vO[k]) for k, name in enumerate(self.model.names)]

    def joint_states(self) -> JointStates:
        """Euler angles of spherical joints, hinge angles, rotor angles (docs/scene-format.md); the same
        numbers as `snapshot()`, which logs re-simulate against."""
        pos, vel, eff = self._outputs.joint_arrays()
        return JointStates(list(self._joint_names), pos.tolist(), vel.tolist(), eff.tolist())

    def wrenches(self) -> list[Wrench]:
        """R^k (eq 40) and L^k (eq 48) at every joint, in the body's own frame."""
        force, moment = self._outputs.wrenches()
        return [Wrench(name, name, force[k], moment[k]) for k, name in enumerate(self.model.names)]

    def invariants(self) -> dict[str, float]:
        """Energy (eq 33 + gravity potential), vertical momentum about O^1, and what else applies.

        Chains of Lagrange gyroscopes add the paper's own integrals in Euler angles:
        "lagrange_82" (eq 82, = -vertical_momentum) and "lagrange_85" (eq 85, = 2 (energy - const),
        see :func:`gyro_sim.analytic.lagrange.physical_invariants`).
        """
        now, euler = self._outputs.invariants(self._lagrange is not None)
        if euler is not None:
            self._add_lagrange(now, *euler)
        return now

    def _add_lagrange(self, out: dict, euler, rates) -> None:
        """The paper's own integrals of a Lagrange chain, from the Euler angles and rates."""
        from gyro_sim.analytic.lagrange import energy_integral_85, vertical_momentum_82

        out["lagrange_82"] = vertical_momentum_82(self._lagrange, euler, rates)  # = -vertical_momentum
        out["lagrange_85"] = energy_integral_85(self._lagrange, euler, rates)  # = 2 (T + V - const)

    # --- the snapshot: everything the outside sees, once per publication ---------------------------
    @property
    def work(self) -> float:
        """Work done by the commanded axis moments since the last reset (J): the sum over
        `advance` calls of moment * change of the axis angle (exact under the zero-order hold),
        the moments saturated to their max_torque. With state-dependent actuator terms
        (friction, max_speed, servos) the integral of the motors' and the servos' power, a
        state integrated with the motion."""
        return self._work

    @property
    def friction_work(self) -> float:
        """Work done by friction since the last reset (J, <= 0: the energy dissipated), the
        integral of friction torque x relative speed; 0 without friction."""
        exact = 0.0 if self._coulomb is None else self._coulomb.work  # the exact Coulomb friction of hinges and rotors
        return (float(self._y[self.model.i_work][1]) if self.model.stateful else 0.0) + exact

    @property
    def saturated_commands(self) -> int:
        """Commanded axis moments clipped to their max_torque since the last reset (each value
        of `set_axis_moments` beyond its axis's limit counts once)."""
        return self._saturated

    @property
    def backend(self) -> str:
        """"numba" or "numpy": which dynamics the Simulator runs."""
        return self.system.backend

    def reference_invariants(self) -> dict:
        """The invariants of the state at the last reset (what drifts are measured against)."""
        if self._reference is None:
            if self._t != 0.0:
                raise RuntimeError("the reference is taken at the reset state")
            self._reference = self.invariants()
        return self._reference

    def snapshot(self, *, bodies: bool = True, wrenches: bool = True, invariants: bool = True,
                 into: Scatter | None = None) -> Snapshot:
        """The outputs at the current time (gyro_sim.snapshot.Snapshot); parts switched off
        are None and not computed. On the numba backend every part comes from one compiled call
        (`gyro_sim.dynamics.outputs.publication_kernel`), else from the numpy reference; both
        agree to round-off. `into`: also write the joint states, poses and wrenches into the
        slots of a Scatter (the parts it has slots for must be asked)."""
        parts = self._outputs.parts(bodies, wrenches, invariants, self._lagrange is not None, into)
        kw = parts.arrays
        if invariants:
            if parts.euler is not None:
                self._add_lagrange(parts.invariants, *parts.euler)
            kw.update(self._invariant_parts(parts.invariants))
        snap = self._snapshot(parts.position, parts.velocity, parts.effort, kw, arrays_checked=parts.checked)
        if into is not None and not parts.written:
            into.write(snap)
        return snap

    def write_outputs(self, into: Scatter, *, bodies: bool = True, wrenches: bool = True) -> str | None:
        """The joint states, and the poses (`bodies`) and wrenches asked for, of the current state
        written into the slots of `into` only, without a Snapshot (a publication without
        diagnostics: gyro_sim.ros.outputs); the slots `into` has must be asked. Returns None when
        every number written is finite, else the field `Snapshot.nonfinite` names (the slots
        then hold what was found: not to be sent). Same numbers as `snapshot(into=...)`."""
        if self._outputs.write(into, bodies, wrenches) and math.isfinite(self._t):
            return None
        # the name Snapshot.nonfinite gives (its order of the fields), from a snapshot of the state
        return self.snapshot(bodies=bodies, wrenches=wrenches, invariants=False).nonfinite() or "time"

    def _invariant_parts(self, now: dict) -> dict:
        """The snapshot's invariants, drifts since the reset, work and energy balance."""
        ref = self.reference_invariants()
        kw = {"invariants": now,
              "drift": {name: inv.relative_drift(name, ref, now[name]) for name in self._conserved},
              "work": self._work}
        if self.model.actuators is not None:
            kw["friction_work"], kw["saturated_commands"] = self.friction_work, self._saturated
        if self._balanced is not None:  # the energy's, or with speed rotors the Jacobi integral's
            b = self._balanced
            kw["energy_balance"] = now[b] - ref[b] - self._work - self.friction_work
            kw["energy_scale"] = inv.drift_scale(b, ref)
        return kw

    def _snapshot(self, pos, vel, eff, kw: dict, arrays_checked: bool = False) -> Snapshot:
        names = self._snapshot_names
        return Snapshot(
            time=self._t, joint_names=names[0], position=pos, velocity=vel, effort=eff, axis_names=names[1],
            axis_moments=self._moments.copy(), integrator=self.integrator_name, error_estimate=self.error_estimate,
            body_names=names[2], arrays_checked=arrays_checked, **self._method_fields(), **kw)

    def _method_fields(self) -> dict:
        """The chooser's state ("fixed" integrator), for the snapshot."""
        integ = self.integrator
        if not getattr(integ, "current", ""):
            return {}
        hl = getattr(integ, "h_lambda", None)
        return {"method": integ.current, "method_reason": integ.reason, "substeps": getattr(integ, "substeps", None),
                "h_lambda": hl if hl is not None and math.isfinite(hl) else None,
                "budget_calls": getattr(integ, "budget_calls", None),
                "budget_energy_error": getattr(integ, "budget_energy_error", None)}

    # --- IMUs ---------------------------------------------------------------------------------
    @property
    def imu_names(self) -> tuple[str, ...]:
        """The scene's IMUs, in scene order (empty without IMUs)."""
        return () if self._imus is None else self._imus.names

    @property
    def imu_rates(self) -> tuple[float, ...]:
        """Each IMU's rate (Hz): the scene's, else the default (`set_imu_default_rate`)."""
        return () if self._imus is None else self._imus.rates

    def set_imu_default_rate(self, rate: float) -> None:
        """The rate of the IMUs whose scene gives none (Hz; the node and `gyro-sim run` set their
        publish rate); their noise generators start again."""
        if self._imus is not None:
            self._imus.set_default_rate(self.scene, float(rate))

    def imus(self):
        """What each IMU of the scene reads now (gyro_sim.dynamics.imu.ImuReading, scene order; []
        without IMUs): gyro, accelerometer (specific force) and orientation, with the scene's
        noise of the sample the current time falls in (sample floor(t rate)). From the
        accelerations of one dynamics evaluation at the current state and commands (on the numba
        backend those a publication with wrenches left, when it was of this state); both backends
        agree to round-off."""
        if self._imus is None:
            return []
        return self._imus.read(self._t, *self._outputs.accelerations())

    def linearize(self, y: np.ndarray | None = None, spins: np.ndarray | None = None, *, method: str = "complex",
                  rotor_angles: bool = False, chart: str = "world", frame_rate=None):
        """The linear model dx' = A dx + B du + f0 at the current state and held commands, or at
        the state `y` (the model's layout) and torque-rotor `spins`: a
        :class:`gyro_sim.linear.Linearization` (names, eigenvalues, verdict, `discrete(h)`;
        docs/linearization.md). method "complex" (exact) or "fd" (central differences); chart
        "world", "body" (co-rotating with a steady spin) or "frame" (a frame turning at
        `frame_rate`, world axes: a regular precession's)."""
        from gyro_sim.linear import linearize

        m = self.model
        y = self._y if y is None else np.asarray(y, dtype=float)
        if spins is None:
            spins = y[m.i_spin] if m.stateful else self._p
        return linearize(m, self._t, y, spins, self._moments, method=method, rotor_angles=rotor_angles, chart=chart,
                         frame_rate=frame_rate, controls=self._controls)
