"""What the Simulator shows of a state, by one of two backends with the same methods: the numpy
reference (:class:`NumpyOutputs`, from :mod:`gyro_sim.dynamics.reference`) and the compiled
outputs (:class:`CompiledOutputs`, one call of
:func:`gyro_sim.dynamics.outputs.publication_kernel`). Both agree to round-off
(test/dynamics/test_outputs.py); a log re-simulates bit for bit against either.

Each is given the state and the commands (`moved`, `commanded`) and computes on request only:
the joint states, the bodies' poses and velocities, the wrenches, the invariants, the
accelerations the IMUs read, and the energies the "fixed" integrator's watchdog compares. A
Scatter (gyro_sim.snapshot) is what it writes into: `dst` and its slot arrays.
"""
from __future__ import annotations

from types import SimpleNamespace
from typing import Callable, NamedTuple

import numpy as np

from gyro_sim.dynamics import invariants as inv
from gyro_sim.dynamics import outputs as fo
from gyro_sim.dynamics import reference as dyn
from gyro_sim.dynamics.rotations import matrices_to_euler, matrix_to_quat, omegas_to_euler_rates

#: the held inputs of the current commands: (hinge moments (nh,), rotor torques (nt,)), each or None
Inputs = Callable[[], tuple]


def joint_sources(model, joint_index: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The joint-state entries as the compiled outputs take them: (kind, ref) (J,) int64, kind one
    of fo.JOINT_* (the sources of the Simulator's joint layout, decoded: the Euler angles of
    every body (3 n), the hinges, the torque rotors, the speed rotors)."""
    m = model
    n, nh, nt = m.n, len(m.hinge_bodies), len(m.torque_body)
    kind, ref = [], []
    for i in joint_index.tolist():
        if i < 3 * n:
            kind.append(fo.JOINT_EULER), ref.append(i)
        elif i < 3 * n + nh:
            kind.append(fo.JOINT_HINGE), ref.append(int(m.hinge_bodies[i - 3 * n]))
        elif i < 3 * n + nh + nt:
            kind.append(fo.JOINT_TORQUE_ROTOR), ref.append(i - 3 * n - nh)
        else:
            kind.append(fo.JOINT_SPEED_ROTOR), ref.append(i - 3 * n - nh - nt)
    return np.array(kind, dtype=np.int64), np.array(ref, dtype=np.int64)


def _invariants_dict(model, v: np.ndarray) -> dict:
    """The invariants (as gyro_sim.dynamics.invariants.invariants) from fo.INV_* entries."""
    now = {"energy": float(v[fo.INV_ENERGY]), "kinetic": float(v[fo.INV_KINETIC]),
           "potential": float(v[fo.INV_POTENTIAL])}
    if model.lam_speed is not None:
        now["jacobi"] = float(v[fo.INV_JACOBI])
    now["angular_momentum_O1"] = v[fo.INV_H_O1].copy()
    now["vertical_momentum"] = float(v[fo.INV_VERTICAL])
    if model.free:
        now["linear_momentum"] = v[fo.INV_P].copy()
        now["angular_momentum"] = v[fo.INV_L_COM].copy()
    return now


class Parts(NamedTuple):
    """What a snapshot shows of the current state, as a backend computes it."""

    position: np.ndarray  # the joint states (J,)
    velocity: np.ndarray
    effort: np.ndarray
    arrays: dict  # the poses and wrenches asked, by the snapshot's names
    invariants: dict | None  # as gyro_sim.dynamics.invariants.invariants; None when not asked
    euler: tuple | None  # Euler angles and rates (n, 3) when asked with the invariants
    checked: bool  # the arrays were found finite
    written: bool  # `into` was written (else the caller writes the snapshot into it)


class _State:
    """The state and commands both backends are given."""

    def __init__(self, model, system, joint_index: np.ndarray, inputs: Inputs):
        self.model, self.system, self.inputs = model, system, inputs
        self.joint_index = joint_index
        self.t, self.y, self.p, self.moments = 0.0, None, None, None


class NumpyOutputs(_State):
    """The outputs from the numpy reference, in the system's output workspace (`system.data`);
    what the compiled outputs are tested against.

    model : the compiled model; system : its ODE system (ChainODE or FastChainODE: `hold`, `rhs`
    with `out`, `spins`, `data`); joint_index : where each joint-state entry comes from (see
    `joint_sources`); inputs : the held inputs of the current commands
    """

    def __init__(self, model, system, joint_index: np.ndarray, inputs: Inputs):
        super().__init__(model, system, joint_index, inputs)
        self._cache = None  # the evaluation of the current state and commands
        self._kin_ok = False  # system.data holds the current state's kinematics
        self._watch_data = None  # the watchdog's own workspace

    def moved(self, t: float, y: np.ndarray, p, moments: np.ndarray) -> None:
        """A new state (and commands): nothing computed holds."""
        self.t, self.y, self.p, self.moments = t, y, p, moments
        self._cache = None
        self._kin_ok = False

    def commanded(self, moments: np.ndarray) -> None:
        """New commands at the same state: the kinematics hold, the rest not."""
        self.moments = moments
        self._cache = None

    def stale(self) -> None:
        """The workspaces were written by others (an integration under way): nothing holds."""
        self._cache = None
        self._kin_ok = False

    def _evaluate(self) -> dyn.Evaluation:
        """One dynamics evaluation at the current state, with everything outputs need."""
        if self._cache is None:
            hinge_tau, L_rotor = self.inputs()
            self.system.hold(self.t, self.p, hinge_tau, L_rotor)
            ev = dyn.Evaluation()
            self.system.rhs(self.t, self.y, out=ev)
            self._cache = ev
            self._kin_ok = True  # the evaluation left the current state's kinematics in data
        return self._cache

    def kinematics(self) -> dyn.Data:
        """Positions and velocities of the current state in the output workspace, computed once
        per state (outputs asked together share them)."""
        d = self.system.data
        if not self._kin_ok:
            dyn.positions(self.model, d, self.t, self.y)
            dyn.velocities(self.model, d, self.t, self.y[self.model.i_vel])
            self._kin_ok = True
        return d

    def energies(self, t: float, y: np.ndarray) -> np.ndarray:
        """fo.INV_* at (t, y) with the inputs the system holds (no new hold), in a workspace of
        its own: the energies (INV_ENERGY, INV_KINETIC, INV_POTENTIAL, INV_JACOBI), the rest
        zero; a new array."""
        d = self._watch_data
        if d is None:
            d = self._watch_data = dyn.Data(self.model)
        dyn.positions(self.model, d, t, y)
        dyn.velocities(self.model, d, t, y[self.model.i_vel])
        v = inv.invariants(self.model, d, self.system.spins(t, y), t, y)
        out = np.zeros(fo.INV_SIZE)
        out[fo.INV_ENERGY], out[fo.INV_KINETIC], out[fo.INV_POTENTIAL] = v["energy"], v["kinetic"], v["potential"]
        out[fo.INV_JACOBI] = v.get("jacobi", 0.0)
        return out

    def _euler(self, d: dyn.Data) -> tuple[np.ndarray, np.ndarray]:
        """Euler angles and rates (n, 3) of every body."""
        euler = matrices_to_euler(d.R, self.model.down)
        return euler, omegas_to_euler_rates(euler, d.w, self.model.down)

    def joint_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """position, velocity, effort (J,) of the joint states."""
        m = self.model
        ev = self._evaluate() if len(m.speed_body) else None
        d = self.kinematics()
        hinge_tau, L_rotor = self.inputs()
        euler, rates = self._euler(d)
        kdot_t = dyn.torque_rotor_rates(m, d, self.p) if len(m.torque_body) else np.zeros(0)  # (18-19)
        L_v = np.zeros(0)
        if len(m.speed_body):  # the motor keeps kappa_i' constant: L_i = A_i (w' . e_i)
            e_v = dyn.matvec(d.R[m.speed_body], m.speed_axis)
            L_v = m.speed_A * np.einsum("ni,ni->n", ev.acc_w[m.speed_body], e_v)
        if m.stateful:  # the torques applied at this state: motors after saturation and cut, friction
            self._evaluate()
            a = self.system.data.applied
            hinge_tau, L_rotor = a.hinge_motor + a.hinge_friction, a.rotor_motor + a.rotor_friction
        nh, nt = len(m.hinge_bodies), len(m.torque_body)
        u = self.y[m.i_vel]
        pos = np.concatenate((euler.ravel(), self.y[m.i_phi], self.y[m.i_kappa], m.speed_rate * self.t))
        vel = np.concatenate((rates.ravel(), u[m.col_hinge], kdot_t, m.speed_rate))
        eff = np.concatenate((np.zeros(3 * m.n), np.zeros(nh) if hinge_tau is None else hinge_tau,
                              np.zeros(nt) if L_rotor is None else L_rotor, L_v))
        i = self.joint_index
        return pos[i], vel[i], eff[i]

    def bodies(self) -> tuple[np.ndarray, ...]:
        """O, R, quat, w, vO of every body: joint points (n, 3), world_R_body (n, 3, 3),
        quaternions (n, 4), angular velocities and velocities of the joint points (n, 3)."""
        m = self.model
        d = self.kinematics()
        q = np.empty((m.n, 4))
        if len(m.sph_bodies):
            qs = self.y[m.i_quat]
            q[m.sph_bodies] = qs / np.linalg.norm(qs, axis=1, keepdims=True)
        for k in m.hinge_bodies:
            q[k] = matrix_to_quat(d.R[k])
        return d.O.copy(), d.R.copy(), q, d.w.copy(), d.vO.copy()

    def wrenches(self) -> tuple[np.ndarray, np.ndarray]:
        """R^k (eq 40) and L^k (eq 48) (n, 3), in body k's frame."""
        ev = self._evaluate()
        d = self.system.data
        R, L = dyn.reactions(self.model, d, ev.f_ang, ev.f_lin)
        Rt = d.R.transpose(0, 2, 1)
        return dyn.matvec(Rt, R), dyn.matvec(Rt, L)

    def invariants(self, euler: bool = False) -> tuple[dict, tuple | None]:
        """The invariants (gyro_sim.dynamics.invariants.invariants), and the Euler angles and
        rates (n, 3) when `euler` is asked (else None)."""
        d = self.kinematics()
        return inv.invariants(self.model, d, self.p, self.t, self.y), (self._euler(d) if euler else None)

    def parts(self, bodies: bool, wrenches: bool, invariants: bool, euler: bool, into=None) -> Parts:
        """What a snapshot shows, the parts asked (`euler`: the Euler angles with the
        invariants); `into` is not written here."""
        pos, vel, eff = self.joint_arrays()
        kw = {}
        if bodies:
            O, _, q, _, _ = self.bodies()
            kw["body_position"], kw["body_quaternion"] = O, q
        if wrenches:
            kw["wrench_force"], kw["wrench_moment"] = self.wrenches()
        now, eul = self.invariants(euler) if invariants else (None, None)
        return Parts(pos, vel, eff, kw, now, eul, False, False)

    def write(self, into, bodies: bool, wrenches: bool) -> bool:
        """The joint states, and the poses and wrenches asked, into the slots of `into`; whether
        every number written is finite."""
        pos, vel, eff, kw = self.parts(bodies, wrenches, False, False)[:4]
        into.write(SimpleNamespace(position=pos, velocity=vel, effort=eff, **kw))  # read as a snapshot
        found = (pos, vel, eff, *kw.values())
        return all(np.all(np.isfinite(a)) for a in found)

    def accelerations(self) -> tuple[np.ndarray, ...]:
        """R, w, vO, alpha, a_s(O^k) (n, ...) of one evaluation at the current state and commands
        (what the IMUs read)."""
        ev = self._evaluate()
        d = self.system.data
        a_s = ev.acc_v + dyn.cross(ev.acc_w, d.O)  # about O^k
        return d.R, d.w, d.vO, ev.acc_w, a_s


class CompiledOutputs(_State):
    """The outputs from one compiled call (fo.publication_kernel) into scratch arrays of its own,
    under held inputs of its own (the system keeps the hold of the last advance); a stateful
    model's efforts are the torques applied at the state, as the numpy reference's.

    model, system (FastChainODE: `kernel_arguments`, `records_with_own_inputs`), joint_index,
    inputs : as NumpyOutputs
    """

    def __init__(self, model, system, joint_index: np.ndarray, inputs: Inputs):
        super().__init__(model, system, joint_index, inputs)
        self.kernel = None  # made, with the scratch, on the first call (`_setup`)
        self._acc_ok = False  # the scratch holds the accelerations of the current state
        self._watch_joints = None

    def moved(self, t: float, y: np.ndarray, p, moments: np.ndarray) -> None:
        """A new state (and commands): nothing computed holds."""
        self.t, self.y, self.p, self.moments = t, y, p, moments
        self._acc_ok = False

    def commanded(self, moments: np.ndarray) -> None:
        """New commands at the same state."""
        self.moments = moments
        self._acc_ok = False

    def stale(self) -> None:
        """The scratch was written by others (the watchdog's calls during an integration)."""
        self._acc_ok = False

    def _setup(self) -> None:
        """What the compiled outputs take beyond the dynamics kernel's records, and their scratch
        arrays: made once, on the first call."""
        from gyro_sim import jit

        m = self.model
        n, nv = m.n, len(m.speed_body)
        self._layout = fo.layout(m, *joint_sources(m, self.joint_index))
        self.scratch = {
            "ydot": np.zeros(m.size), "R": np.zeros((n, 3, 3)), "w": np.zeros((n, 3)), "vO": np.zeros((n, 3)),
            "O": np.zeros((n, 3)), "quat": np.zeros((n, 4)), "euler": np.zeros((n, 3)), "euler_rate": np.zeros((n, 3)),
            "L_speed": np.zeros(nv), "wrench_force": np.zeros((n, 3)), "wrench_moment": np.zeros((n, 3)),
            "inv": np.zeros(fo.INV_SIZE), "scratch": np.zeros(fo.scratch_size(n))}
        self._outputs = fo.Outputs(*(self.scratch[k] for k in fo.OUTPUT_NAMES))
        J = len(self.joint_index)
        self._no_slots = fo.Slots(np.zeros(0), *(np.zeros((0, *shape), dtype=np.int64)
                                                for shape in ((3, J), (n, 3), (n, 4), (n, 6))))
        # the kernel's records with held inputs of the publications' own (`_held_now`)
        self._records = self.system.records_with_own_inputs()
        self._held_moments = None  # the commanded moments of the inputs held there
        self._joints = fo.JointStates(np.empty(J), np.empty(J), np.empty(J))  # write's joint states
        self.kernel = jit.Direct(fo.publication_kernel)

    def energies(self, t: float, y: np.ndarray) -> np.ndarray:
        """fo.INV_* at (t, y) with the inputs the system holds (those of the call under way: no
        new hold), computing nothing else but the joint states (WANT_INVARIANTS); a new array.
        Overwrites the scratch."""
        if self.kernel is None:
            self._setup()
        J = len(self.joint_index)
        js = self._watch_joints
        if js is None or js.position.shape[0] != J:
            js = self._watch_joints = fo.JointStates(np.empty(J), np.empty(J), np.empty(J))
        self._acc_ok = False
        self.kernel(float(t), np.ascontiguousarray(y, dtype=np.float64), self.scratch["ydot"],
                    *self.system.kernel_arguments(), self._layout, int(fo.WANT_INVARIANTS), self._outputs, js,
                    self._no_slots)
        return self.scratch["inv"].copy()

    def _held_now(self) -> None:
        """Hold in the publications' own inputs from now on what `system.hold(t, p, *inputs())`
        would hold, without holding it in the system: only t0 and the spins change from one
        publication to the next; the rest is written again only when the commands change."""
        inputs = self._records[2]
        if self._held_moments is not self.moments:
            fo.hold(inputs, self.model, self.t, self.p, *self.inputs())
            self._held_moments = self.moments
        else:
            inputs.t0[0] = self.t
            if self.p is not None:
                inputs.p0[:] = self.p

    def call(self, want: int, into, states: fo.JointStates) -> int:
        """fo.publication_kernel at the current state: the outputs into the scratch arrays, the
        joint states into `states`, the numbers also into the slots of `into` (None: nowhere);
        returns the index in fo.NONFINITE_FIELDS of a field found not finite (0: none)."""
        if self.kernel is None:
            self._setup()
        y = self.y
        if y.dtype != np.float64 or not y.flags.c_contiguous:  # the compiled entry does not convert
            y = self.y = np.ascontiguousarray(y, dtype=np.float64)
        self._held_now()
        slots = self._no_slots if into is None else fo.Slots(into.dst, into.joint, into.position, into.quaternion,
                                                            into.wrench)
        bad = self.kernel(float(self.t), y, self.scratch["ydot"], *self._records, self._layout, want, self._outputs,
                          states, slots)
        self._acc_ok = bool(want & fo.WANT_WRENCHES or len(self.model.speed_body))
        return bad

    def outputs(self, want: int | None = None, into=None, fresh: bool = True) -> dict:
        """The outputs of the current state from one compiled call: the scratch arrays by name
        (those of FastChainODE.outputs), and the joint states "position", "velocity", "effort"
        (new arrays), "nonfinite" (0, or the index in fo.NONFINITE_FIELDS of a field found not
        finite). want: WANT_* bits (None: every part); into: a Scatter to write into as well.
        fresh=False: the other arrays are the scratch, valid until the next call."""
        J = len(self.joint_index)
        states = fo.JointStates(np.empty(J), np.empty(J), np.empty(J))
        bad = self.call(int(fo.WANT_ALL if want is None else want), into, states)
        o = self.scratch
        out = {k: v.copy() for k, v in o.items() if k != "scratch"} if fresh else dict(o)
        out.update(position=states.position, velocity=states.velocity, effort=states.effort, nonfinite=bad)
        return out

    def joint_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """position, velocity, effort (J,) of the joint states."""
        o = self.outputs()
        return o["position"], o["velocity"], o["effort"]

    def bodies(self) -> tuple[np.ndarray, ...]:
        """O, R, quat, w, vO of every body (as NumpyOutputs.bodies)."""
        o = self.outputs()
        return o["O"], o["R"], o["quat"], o["w"], o["vO"]

    def wrenches(self) -> tuple[np.ndarray, np.ndarray]:
        """R^k (eq 40) and L^k (eq 48) (n, 3), in body k's frame."""
        o = self.outputs()
        return o["wrench_force"], o["wrench_moment"]

    def invariants(self, euler: bool = False) -> tuple[dict, tuple | None]:
        """The invariants, and the Euler angles and rates when `euler` is asked (else None)."""
        o = self.outputs()
        return _invariants_dict(self.model, o["inv"]), ((o["euler"], o["euler_rate"]) if euler else None)

    def parts(self, bodies: bool, wrenches: bool, invariants: bool, euler: bool, into=None) -> Parts:
        """As NumpyOutputs.parts, from one compiled call that also writes into `into`."""
        want = (fo.WANT_BODIES if bodies else 0) | (fo.WANT_WRENCHES if wrenches else 0)
        if invariants:
            want |= fo.WANT_INVARIANTS | (fo.WANT_EULER_ALL if euler else 0)
        o = self.outputs(want, into, fresh=False)
        kw = {}
        if bodies:
            kw["body_position"], kw["body_quaternion"] = o["O"].copy(), o["quat"].copy()
        if wrenches:
            kw["wrench_force"], kw["wrench_moment"] = o["wrench_force"].copy(), o["wrench_moment"].copy()
        now = _invariants_dict(self.model, o["inv"]) if invariants else None
        eul = (o["euler"], o["euler_rate"]) if invariants and euler else None
        return Parts(o["position"], o["velocity"], o["effort"], kw, now, eul, o["nonfinite"] == 0, True)

    def write(self, into, bodies: bool, wrenches: bool) -> bool:
        """The joint states, and the poses and wrenches asked, into the slots of `into`; whether
        every number written is finite."""
        if self.kernel is None:
            self._setup()
        want = (fo.WANT_BODIES if bodies else 0) | (fo.WANT_WRENCHES if wrenches else 0)
        return self.call(want, into, self._joints) == 0

    def accelerations(self) -> tuple[np.ndarray, ...]:
        """R, w, vO, alpha, a_s(O^k) (n, ...) of one evaluation at the current state and commands:
        those the last call left when it made them for this state, else from a call now."""
        from gyro_sim.dynamics.imu import compiled_accelerations

        if self.kernel is None:
            self._setup()
        if not self._acc_ok:
            self.call(fo.WANT_WRENCHES, None, self._joints)
        o = self.scratch
        alpha, a_s = compiled_accelerations(o["scratch"], self.model.n)
        return o["R"], o["w"], o["vO"], alpha, a_s
