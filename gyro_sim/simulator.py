"""The Simulator: the stable Python API (README, "Python API") over model, dynamics and integrators."""
from __future__ import annotations

import math
import os
from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np

from gyro_sim.errors import GyroSimError
from gyro_sim.dynamics import reference as dyn
from gyro_sim.dynamics import invariants as inv
from gyro_sim.dynamics.model import compile_model, initial_state
from gyro_sim.dynamics.rotations import matrices_to_euler, omegas_to_euler_rates
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

        self.integrator = make_integrator(integrator, self.system, rtol=rtol, atol=atol, step=step)
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
        if m.stateful and integrator not in STATEFUL_INTEGRATORS:
            from gyro_sim.dynamics.actuators import ActuatorError

            raise ActuatorError(f"{m.actuators.terms[0]}: integrator {integrator!r} does not take speed-dependent "
                             f"actuator terms (friction, max_speed); use one of {', '.join(STATEFUL_INTEGRATORS)}")
        self._joint_layout()
        # snapshots from compiled code when the system has it (the numba backend)
        # (a stateful model's outputs, its applied torques, come from the numpy reference)
        self._compiled_outputs = None if m.stateful else getattr(self.system, "outputs", None)
        self._watched = self._watched_energy()
        self._watch_last = None
        self._watch_joints = None
        if self._watched is not None and getattr(self.integrator, "monitor", False) is None:
            self.integrator.monitor = self._energy_error  # "fixed": its energy watchdog
        self._imus = None  # the IMUs (gyro_sim.dynamics.imu.ImuSet), when the scene has some
        self._acc_ok = False  # the compiled scratch holds the accelerations of the current state
        if scene.imus:
            from gyro_sim.dynamics.imu import DEFAULT_IMU_RATE, ImuSet

            self._imus = ImuSet(scene, {b.name: k for k, b in enumerate(scene.bodies)}, scene.gravity,
                                DEFAULT_IMU_RATE)
        self.reset()

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
        invariants (`_invariants_at`)."""
        from gyro_sim.dynamics import outputs as fast_outputs

        if self._balanced == "energy":
            return fast_outputs.INV_ENERGY
        return fast_outputs.INV_JACOBI if self._balanced == "jacobi" else None

    def _energy_error(self, t0: float, y0: np.ndarray, t1: float, y1: np.ndarray) -> float:
        """How far an integrator's call from (t0, y0) to (t1, y1) breaks the energy balance,
        relative to the kinetic energy: (E1 - E0 - W) / max(T0, T1), W the work of the held
        moments (exact under the zero-order hold); 0 where no balance holds (Jacobi integral
        with moments commanded). The kinetic energy, not T + |V|: the potential's zero is
        arbitrary, and a step that does not resolve the motion errs in proportion to the motion.
        Called by the "fixed" integrator after each call."""
        moving = len(self._axis_angle) and np.any(self._moments)
        if self.model.stateful:  # the applied torques' work is a state: the motors', friction's
            moving = True
        if self._watched is None or (moving and self._balanced != "energy"):
            return 0.0
        if self.model.stateful:
            w = self.model.i_work
            work = float(np.sum(y1[w] - y0[w]))
        else:
            i = self._axis_angle
            work = float(self._inputs_moments() @ (y1[i] - y0[i])) if moving else 0.0
        from gyro_sim.dynamics.outputs import INV_KINETIC

        last = self._watch_last  # the previous call's end is usually this one's start
        v0 = last[2] if last is not None and last[0] == t0 and np.array_equal(last[1], y0) \
            else self._invariants_at(t0, y0)
        v1 = self._invariants_at(t1, y1)
        self._watch_last = (t1, y1.copy(), v1)
        scale = max(v0[INV_KINETIC], v1[INV_KINETIC], 1e-300)
        return float((v1[self._watched] - v0[self._watched] - work) / scale)

    def _invariants_at(self, t: float, y: np.ndarray) -> np.ndarray:
        """The compiled invariants (fast_outputs.INV_*) at (t, y) with the inputs the system
        holds (those of the call under way: no new hold), computing nothing else but the joint
        states (fast_outputs.publication_kernel with WANT_INVARIANTS); a new array. On the numpy
        backend the energies (INV_ENERGY, INV_KINETIC, INV_POTENTIAL, INV_JACOBI) from the
        numpy invariants, the rest zero."""
        from gyro_sim.dynamics import outputs as fo

        if self._compiled_outputs is None:  # numpy backend: the reference invariants, own workspace
            d = getattr(self, "_watch_data", None)
            if d is None:
                d = self._watch_data = dyn.Data(self.model)
            dyn.positions(self.model, d, t, y)
            dyn.velocities(self.model, d, t, y[self.model.i_vel])
            v = inv.invariants(self.model, d, self.system.spins(t, y), t)
            out = np.zeros(fo.INV_SIZE)
            out[fo.INV_ENERGY], out[fo.INV_KINETIC], out[fo.INV_POTENTIAL] = v["energy"], v["kinetic"], v["potential"]
            out[fo.INV_JACOBI] = v.get("jacobi", 0.0)
            return out
        if getattr(self, "_snapshot_kernel", None) is None:
            self._snapshot_setup()
        o = self._snapshot_scratch
        J = len(self._joint_names)
        js = self._watch_joints
        if js is None or js.position.shape[0] != J:
            js = self._watch_joints = fo.JointStates(np.empty(J), np.empty(J), np.empty(J))
        self._snapshot_kernel(
            float(t), np.ascontiguousarray(y, dtype=np.float64), o["ydot"], *self.system.kernel_arguments(),
            self._snapshot_layout, int(fo.WANT_INVARIANTS), self._snapshot_outputs, js, self._snapshot_no_slots)
        return o["inv"].copy()

    def _joint_layout(self) -> None:
        """The joint-state entries in order (docs/scene-format.md, "Joint states"): their names, and where each entry's
        position, velocity and effort come from in the sources of `_joint_arrays`: the Euler
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

    def _joint_arrays(self, euler, rates, kdot_t, L_v, hinge_tau, L_rotor):
        """position, velocity, effort (J,) of the joint states from their sources (see
        `_joint_layout`): euler, rates (n, 3); kdot_t (nt,) torque-rotor angle rates; L_v (nv,)
        speed-rotor motor torques; the held commands (None: zero)."""
        m = self.model
        nh, nt = len(m.hinge_bodies), len(m.torque_body)
        u = self._y[m.i_vel]
        pos = np.concatenate((euler.ravel(), self._y[m.i_phi], self._y[m.i_kappa], m.speed_rate * self._t))
        vel = np.concatenate((rates.ravel(), u[m.col_hinge], kdot_t, m.speed_rate))
        eff = np.concatenate((np.zeros(3 * m.n), np.zeros(nh) if hinge_tau is None else hinge_tau,
                              np.zeros(nt) if L_rotor is None else L_rotor, L_v))
        i = self._joint_index
        return pos[i], vel[i], eff[i]

    # --- state -----------------------------------------------------------------------------
    def reset(self) -> None:
        """Back to the scene's initial state, commands zero."""
        m = self.model
        self._t = 0.0
        self._y = initial_state(m)
        self._p = m.torque_p0.copy() if len(m.torque_body) else None
        self._moments = np.zeros(len(m.axis_names))
        self._saturated = 0  # commanded values clipped to their max_torque since the reset
        self._cache = None
        self._kin_ok = False
        self._acc_ok = False
        self._watch_last = None
        self.integrator.reset()
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

    def set_axis_moments(self, values: Sequence[float]) -> None:
        """Commanded axis moments (N m), one per axis in `axis_names` order, held until changed."""
        v = np.asarray(values, dtype=float).ravel()
        if v.shape != (len(self.model.axis_names),):
            raise ValueError(f"expected {len(self.model.axis_names)} axis moments {self.axis_names}, got {v.size}")
        if not np.all(np.isfinite(v)):
            raise ValueError("axis moments must be finite")
        if self._axis_max_torque is not None:
            self._saturated += int(np.count_nonzero(np.abs(v) > self._axis_max_torque))
        self._moments = v.copy()
        self._cache = None  # reactions and efforts depend on the commands
        self._acc_ok = False

    def _inputs(self):
        """The held inputs (hinge moments (nh,), rotor torques (nt,), or None) from the commanded
        axis moments, saturated to the axes' max_torque."""
        m, v = self.model, self._inputs_moments()
        hinge_tau = L_rotor = None
        if len(v):
            hinge_tau = np.zeros(len(m.hinge_bodies))
            sel = m.axis_hinge >= 0
            hinge_tau[m.axis_hinge[sel]] = v[sel]
            if len(m.torque_body):
                L_rotor = np.zeros(len(m.torque_body))
                sel = m.axis_rotor >= 0
                L_rotor[m.axis_rotor[sel]] = v[sel]
        return hinge_tau, L_rotor

    def held_rhs(self):
        """The right-hand side f(t, y) -> (size,) of the chain with the inputs now in force held,
        as `advance` holds them: for an analysis at the current state (the method choice of the
        "fixed" integrator). Its calls use the output workspace: outputs are computed afresh after."""
        hinge_tau, L_rotor = self._inputs()
        self.system.hold(self._t, self._p, hinge_tau, L_rotor)
        self._cache = None
        self._kin_ok = False
        self._acc_ok = False
        return self.system.rhs

    def advance(self, dt: float) -> None:
        """Integrate `dt` seconds of simulated time with the commands held (zero-order hold)."""
        if not (dt > 0 and math.isfinite(dt)):
            raise ValueError(f"dt must be a positive finite number, got {dt!r}")
        if self._reference is None:  # the drifts' reference is the reset state: keep it before moving
            self._reference = self.invariants()
        self._acc_ok = False  # the energy watchdog's calls overwrite the compiled scratch
        hinge_tau, L_rotor = self._inputs()
        self.system.hold(self._t, self._p, hinge_tau, L_rotor)
        try:
            y = self.integrator.advance(self._t, self._y, self._t + dt)
        except (FloatingPointError, np.linalg.LinAlgError, ArithmeticError) as exc:
            self.integrator.reset()  # its step-size memory is meaningless after a failure
            raise SimulationError(f"t = {self._t:.6g} s: {exc}; state kept at t = {self._t:.6g} s") from exc
        if not np.all(np.isfinite(y)):
            self.integrator.reset()
            raise SimulationError(f"t = {self._t:.6g} s: the state became non-finite; state kept at t = {self._t:.6g} s")
        if self.model.stateful:  # the works are states, integrated with the motion
            self._work = float(y[self.model.i_work][0])
        elif len(self._axis_angle) and np.any(self._moments):
            i = self._axis_angle
            self._work += float(self._inputs_moments() @ (y[i] - self._y[i]))
        self._p = self.system.spins(self._t + dt, y)
        self._t += dt
        self._y = y
        self._cache = None
        self._kin_ok = False
        self._acc_ok = False

    # --- outputs (computed on request only) ------------------------------------------------
    def _evaluate(self) -> dyn.Evaluation:
        """One dynamics evaluation at the current state, with everything outputs need."""
        if self._cache is None:
            hinge_tau, L_rotor = self._inputs()
            self.system.hold(self._t, self._p, hinge_tau, L_rotor)
            ev = dyn.Evaluation()
            self.system.rhs(self._t, self._y, out=ev)
            self._cache = ev
            self._kin_ok = True  # the evaluation left the current state's kinematics in data
        return self._cache

    def _kinematics(self) -> dyn.Data:
        """Positions and velocities of the current state in the output workspace, computed once
        per state (outputs asked together share them; advance() and reset() invalidate)."""
        d = self.system.data
        if not self._kin_ok:
            dyn.positions(self.model, d, self._t, self._y)
            dyn.velocities(self.model, d, self._t, self._y[self.model.i_vel])
            self._kin_ok = True
        return d

    # On the numba backend every output comes from one compiled call (FastChainODE.outputs),
    # the snapshot's and these alike (a log re-simulates bit for bit against any of them); the
    # numpy reference (`_..._numpy`) is what the compiled outputs are tested against.
    def body_states(self) -> list[BodyState]:
        """Pose and velocity of every body."""
        if self._compiled_outputs is None:
            return self._body_states_numpy()
        o = self._outputs_compiled()
        return [BodyState(name, o["O"][k], o["R"][k], o["quat"][k], o["w"][k], o["vO"][k])
                for k, name in enumerate(self.model.names)]

    def _body_states_numpy(self) -> list[BodyState]:
        from gyro_sim.dynamics.rotations import matrix_to_quat

        m = self.model
        d = self._kinematics()
        q = np.empty((m.n, 4))
        if len(m.sph_bodies):
            qs = self._y[m.i_quat]
            q[m.sph_bodies] = qs / np.linalg.norm(qs, axis=1, keepdims=True)
        for k in m.hinge_bodies:
            q[k] = matrix_to_quat(d.R[k])
        return [
            BodyState(name, d.O[k].copy(), d.R[k].copy(), q[k], d.w[k].copy(), d.vO[k].copy())
            for k, name in enumerate(m.names)
        ]

    def _euler(self, d: dyn.Data) -> tuple[np.ndarray, np.ndarray]:
        """Euler angles and rates (n, 3) of every body (output only)."""
        euler = matrices_to_euler(d.R, self.model.down)
        return euler, omegas_to_euler_rates(euler, d.w, self.model.down)

    def joint_states(self) -> JointStates:
        """Euler angles of spherical joints, hinge angles, rotor angles (docs/scene-format.md); the same
        numbers as `snapshot()` (compiled on the numba backend), which logs re-simulate against."""
        if self._compiled_outputs is not None:
            pos, vel, eff = self._joint_arrays_compiled(self._outputs_compiled())
        else:
            pos, vel, eff = self._joint_arrays_numpy()
        return JointStates(list(self._joint_names), pos.tolist(), vel.tolist(), eff.tolist())

    def _joint_arrays_numpy(self):
        """The joint states' arrays from the numpy reference."""
        m = self.model
        ev = self._evaluate() if len(m.speed_body) else None
        d = self._kinematics()
        hinge_tau, L_rotor = self._inputs()
        euler, rates = self._euler(d)
        kdot_t = dyn.torque_rotor_rates(m, d, self._p) if len(m.torque_body) else np.zeros(0)  # (18-19)
        L_v = np.zeros(0)
        if len(m.speed_body):  # the motor keeps kappa_i' constant: L_i = A_i (w' . e_i)
            e_v = dyn.matvec(d.R[m.speed_body], m.speed_axis)
            L_v = m.speed_A * np.einsum("ni,ni->n", ev.acc_w[m.speed_body], e_v)
        if m.stateful:  # the torques applied at this state: motors after saturation and cut, friction
            self._evaluate()
            a = self.system.data.applied
            hinge_tau, L_rotor = a.hinge_motor + a.hinge_friction, a.rotor_motor + a.rotor_friction
        return self._joint_arrays(euler, rates, kdot_t, L_v, hinge_tau, L_rotor)

    def wrenches(self) -> list[Wrench]:
        """R^k (eq 40) and L^k (eq 48) at every joint, in the body's own frame."""
        if self._compiled_outputs is None:
            return self._wrenches_numpy()
        o = self._outputs_compiled()
        return [Wrench(name, name, o["wrench_force"][k], o["wrench_moment"][k])
                for k, name in enumerate(self.model.names)]

    def _wrenches_numpy(self) -> list[Wrench]:
        ev = self._evaluate()
        d = self.system.data
        R, L = dyn.reactions(self.model, d, ev.f_ang, ev.f_lin)
        Rt = d.R.transpose(0, 2, 1)
        R_b, L_b = dyn.matvec(Rt, R), dyn.matvec(Rt, L)
        return [Wrench(name, name, R_b[k], L_b[k]) for k, name in enumerate(self.model.names)]

    def invariants(self) -> dict[str, float]:
        """Energy (eq 33 + gravity potential), vertical momentum about O^1, and what else applies.

        Chains of Lagrange gyroscopes add the paper's own integrals in Euler angles:
        "lagrange_82" (eq 82, = -vertical_momentum) and "lagrange_85" (eq 85, = 2 (energy - const),
        see :func:`gyro_sim.analytic.lagrange.physical_invariants`).
        """
        if self._compiled_outputs is None:
            return self._invariants_numpy()
        return self._invariants_compiled(self._outputs_compiled())

    def _invariants_numpy(self) -> dict[str, float]:
        d = self._kinematics()
        out = inv.invariants(self.model, d, self._p, self._t)
        if self._lagrange is not None:
            self._add_lagrange(out, *self._euler(d))
        return out

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
        the moments saturated to their max_torque. With speed-dependent actuator terms
        (friction, max_speed) the integral of the motors' power, a state integrated with the
        motion."""
        return self._work

    @property
    def friction_work(self) -> float:
        """Work done by friction since the last reset (J, <= 0: the energy dissipated), the
        integral of friction torque x relative speed; 0 without friction."""
        return float(self._y[self.model.i_work][1]) if self.model.stateful else 0.0

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
        if self._compiled_outputs is not None:
            return self._snapshot_compiled(bodies, wrenches, invariants, into)
        snap = self._snapshot_numpy(bodies, wrenches, invariants)
        if into is not None:
            into.write(snap)
        return snap

    def _snapshot_numpy(self, bodies: bool = True, wrenches: bool = True, invariants: bool = True) -> Snapshot:
        pos, vel, eff = self._joint_arrays_numpy()
        kw = {}
        if bodies:
            states = self._body_states_numpy()
            kw["body_position"] = np.array([b.position for b in states])
            kw["body_quaternion"] = np.array([b.quaternion for b in states])
        if wrenches:
            ws = self._wrenches_numpy()
            kw["wrench_force"] = np.array([w.force for w in ws])
            kw["wrench_moment"] = np.array([w.moment for w in ws])
        if invariants:
            kw.update(self._invariant_parts(self._invariants_numpy()))
        return self._snapshot(pos, vel, eff, kw)

    def _snapshot_setup(self) -> None:
        """What the compiled outputs take beyond the dynamics kernel's arguments, and their
        scratch arrays: made once, on the first compiled snapshot."""
        from gyro_sim import jit
        from gyro_sim.dynamics import outputs as fast_outputs

        m = self.model
        n, nv = m.n, len(m.speed_body)
        self._snapshot_kernel = jit.Direct(fast_outputs.publication_kernel)
        self._snapshot_layout = fast_outputs.layout(m, *self._joint_arrays_sources())
        self._snapshot_scratch = {
            "ydot": np.zeros(m.size), "R": np.zeros((n, 3, 3)), "w": np.zeros((n, 3)), "vO": np.zeros((n, 3)),
            "O": np.zeros((n, 3)), "quat": np.zeros((n, 4)), "euler": np.zeros((n, 3)), "euler_rate": np.zeros((n, 3)),
            "L_speed": np.zeros(nv), "wrench_force": np.zeros((n, 3)), "wrench_moment": np.zeros((n, 3)),
            "inv": np.zeros(fast_outputs.INV_SIZE), "scratch": np.zeros(fast_outputs.scratch_size(n))}
        self._snapshot_outputs = fast_outputs.Outputs(*(self._snapshot_scratch[k] for k in fast_outputs.OUTPUT_NAMES))
        J = len(self._joint_names)
        self._snapshot_nowhere = Scatter(np.zeros(0), *(np.zeros((0, *shape), dtype=np.int64)
                                                      for shape in ((3, J), (n, 3), (n, 4), (n, 6))))
        self._snapshot_no_slots = self._slots(self._snapshot_nowhere)
        # the kernel's records with held inputs of the publications' own (`_held_now`)
        self._snapshot_records = self.system.records_with_own_inputs()
        self._snapshot_moments = None  # the commanded moments of the inputs held there
        self._snapshot_joints = (np.empty(J), np.empty(J), np.empty(J))  # write_outputs' joint states
        self._snapshot_want = (fast_outputs.WANT_BODIES, fast_outputs.WANT_WRENCHES)

    def _joint_arrays_sources(self) -> tuple[np.ndarray, np.ndarray]:
        """The joint-state entries for the compiled outputs: (kind, ref) (J,) int64, kind one of
        fast_outputs.JOINT_* (the sources of `_joint_layout`, decoded)."""
        from gyro_sim.dynamics import outputs as fo

        m = self.model
        n, nh, nt = m.n, len(m.hinge_bodies), len(m.torque_body)
        kind, ref = [], []
        for i in self._joint_index.tolist():
            if i < 3 * n:
                kind.append(fo.JOINT_EULER), ref.append(i)
            elif i < 3 * n + nh:
                kind.append(fo.JOINT_HINGE), ref.append(int(m.hinge_bodies[i - 3 * n]))
            elif i < 3 * n + nh + nt:
                kind.append(fo.JOINT_TORQUE_ROTOR), ref.append(i - 3 * n - nh)
            else:
                kind.append(fo.JOINT_SPEED_ROTOR), ref.append(i - 3 * n - nh - nt)
        return np.array(kind, dtype=np.int64), np.array(ref, dtype=np.int64)

    def _held_now(self) -> None:
        """Hold in the publications' own inputs (`_snapshot_records`) from now on what
        `system.hold(t, p, *self._inputs())` would hold, without holding it in the system (which
        keeps the hold of the last advance): only t0 and the spins change from one publication
        to the next; the rest is written again only when the commands change."""
        from gyro_sim.dynamics.outputs import hold

        inputs = self._snapshot_records[2]
        if self._snapshot_moments is not self._moments:
            hold(inputs, self.model, self._t, self._p, *self._inputs())
            self._snapshot_moments = self._moments
        else:
            inputs.t0[0] = self._t
            if self._p is not None:
                inputs.p0[:] = self._p

    @staticmethod
    def _slots(into: Scatter):
        """The slots of `into` as the compiled outputs take them (fast_outputs.Slots)."""
        from gyro_sim.dynamics.outputs import Slots

        return Slots(into.dst, into.joint, into.position, into.quaternion, into.wrench)

    def _compiled_call(self, want: int, into: Scatter, pos, vel, eff) -> int:
        """fast_outputs.publication_kernel at the current state: the outputs into the scratch
        arrays, the joint states into pos, vel, eff (J,), the numbers also into the slots of
        `into`; returns its index in NONFINITE_FIELDS of a field found not finite (0:
        none)."""
        if getattr(self, "_snapshot_kernel", None) is None:
            self._snapshot_setup()
        y = self._y
        if y.dtype != np.float64 or not y.flags.c_contiguous:  # the compiled entry does not convert
            y = self._y = np.ascontiguousarray(y, dtype=np.float64)
        from gyro_sim.dynamics.outputs import JointStates

        t = float(self._t)
        self._held_now()
        slots = self._snapshot_no_slots if into is self._snapshot_nowhere else self._slots(into)
        bad = self._snapshot_kernel(t, y, self._snapshot_scratch["ydot"], *self._snapshot_records,
                                    self._snapshot_layout, want, self._snapshot_outputs, JointStates(pos, vel, eff),
                                    slots)
        if self._imus is not None:  # the IMUs read the accelerations this call left, if it made them
            from gyro_sim.dynamics.outputs import WANT_WRENCHES

            self._acc_ok = bool(want & WANT_WRENCHES or len(self.model.speed_body))
        return bad

    def _outputs_compiled(self, want: int | None = None, into: Scatter | None = None, fresh: bool = True) -> dict:
        """The outputs of the current state from one compiled call
        (fast_outputs.publication_kernel): the arrays of FastChainODE.outputs by name, and the
        joint states "position", "velocity", "effort" (new arrays), "nonfinite" (0, or the index in
        fast_outputs.NONFINITE_FIELDS of a field found not finite). want: WANT_* bits
        (None: every part); into: a Scatter to write into as well. fresh=False: the other arrays
        are the Simulator's scratch, valid until the next call."""
        from gyro_sim.dynamics import outputs as fo

        if getattr(self, "_snapshot_kernel", None) is None:
            self._snapshot_setup()
        J = len(self._joint_names)
        pos, vel, eff = np.empty(J), np.empty(J), np.empty(J)
        bad = self._compiled_call(int(fo.WANT_ALL if want is None else want),
                                  self._snapshot_nowhere if into is None else into, pos, vel, eff)
        o = self._snapshot_scratch
        out = {k: v.copy() for k, v in o.items() if k != "scratch"} if fresh else dict(o)
        out.update(position=pos, velocity=vel, effort=eff, nonfinite=bad)
        return out

    def write_outputs(self, into: Scatter, *, bodies: bool = True, wrenches: bool = True) -> str | None:
        """The joint states, and the poses (`bodies`) and wrenches asked for, of the current state
        written into the slots of `into` only, without a Snapshot (a publication without
        diagnostics: gyro_sim.ros.outputs); the slots `into` has must be asked. Returns None when
        every number written is finite, else the field `Snapshot.nonfinite` names (the slots
        then hold what was found: not to be sent). Same numbers as `snapshot(into=...)`."""
        if self._compiled_outputs is None:
            return self.snapshot(bodies=bodies, wrenches=wrenches, invariants=False, into=into).nonfinite()
        if getattr(self, "_snapshot_kernel", None) is None:
            self._snapshot_setup()
        want_bodies, want_wrenches = self._snapshot_want
        want = (want_bodies if bodies else 0) | (want_wrenches if wrenches else 0)
        if self._compiled_call(want, into, *self._snapshot_joints) or not math.isfinite(self._t):
            # the name Snapshot.nonfinite gives (its order of the fields), from a snapshot of the state
            return self.snapshot(bodies=bodies, wrenches=wrenches, invariants=False).nonfinite() or "time"
        return None

    def _joint_arrays_compiled(self, o: dict):
        return o["position"], o["velocity"], o["effort"]

    def _snapshot_compiled(self, bodies: bool, wrenches: bool, invariants: bool, into: Scatter | None = None) -> Snapshot:
        from gyro_sim.dynamics import outputs as fo

        want = (fo.WANT_BODIES if bodies else 0) | (fo.WANT_WRENCHES if wrenches else 0)
        if invariants:
            want |= fo.WANT_INVARIANTS | (fo.WANT_EULER_ALL if self._lagrange is not None else 0)
        o = self._outputs_compiled(want, into, fresh=False)
        kw = {}
        if bodies:
            kw["body_position"], kw["body_quaternion"] = o["O"].copy(), o["quat"].copy()
        if wrenches:
            kw["wrench_force"], kw["wrench_moment"] = o["wrench_force"].copy(), o["wrench_moment"].copy()
        if invariants:
            kw.update(self._invariant_parts(self._invariants_compiled(o)))
        return self._snapshot(o["position"], o["velocity"], o["effort"], kw, arrays_checked=o["nonfinite"] == 0)

    def _invariants_compiled(self, o: dict) -> dict:
        """The invariants (as gyro_sim.dynamics.invariants.invariants) from the compiled outputs."""
        m, v = self.model, o["inv"]
        now = {"energy": float(v[0]), "kinetic": float(v[1]), "potential": float(v[2])}
        if m.lam_speed is not None:
            now["jacobi"] = float(v[3])
        now["angular_momentum_O1"] = v[5:8].copy()
        now["vertical_momentum"] = float(v[4])
        if m.free:
            now["linear_momentum"] = v[8:11].copy()
            now["angular_momentum"] = v[11:14].copy()
        if self._lagrange is not None:
            self._add_lagrange(now, o["euler"], o["euler_rate"])
        return now

    def _invariant_parts(self, now: dict) -> dict:
        """The snapshot's invariants, drifts since the reset, work and energy balance."""
        ref = self.reference_invariants()
        kw = {"invariants": now,
              "drift": {name: inv.relative_drift(name, ref, now[name]) for name in self._conserved},
              "work": self._work}
        if self.model.actuators is not None:
            kw["friction_work"], kw["saturated_commands"] = self.friction_work, self._saturated
        if self._balanced == "energy":
            kw["energy_balance"] = now["energy"] - ref["energy"] - self._work - self.friction_work
            kw["energy_scale"] = inv.drift_scale("energy", ref)
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
        if self._compiled_outputs is None:
            ev = self._evaluate()
            d = self.system.data
            a_s = ev.acc_v + dyn.cross(ev.acc_w, d.O)  # about O^k
            return self._imus.read(self._t, d.R, d.w, d.vO, ev.acc_w, a_s)
        from gyro_sim.dynamics.imu import compiled_accelerations

        if getattr(self, "_snapshot_kernel", None) is None:
            self._snapshot_setup()
        if not self._acc_ok:
            from gyro_sim.dynamics.outputs import WANT_WRENCHES

            self._compiled_call(WANT_WRENCHES, self._snapshot_nowhere, *self._snapshot_joints)
        o = self._snapshot_scratch
        alpha, a_s = compiled_accelerations(o["scratch"], self.model.n)
        return self._imus.read(self._t, o["R"], o["w"], o["vO"], alpha, a_s)

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
                         frame_rate=frame_rate)
