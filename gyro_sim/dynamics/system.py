"""The chain as an ODE system for the integrators, and the choice of its backend.

    system = make_system(model, backend)        # ChainODE (numpy) or FastChainODE (numba)
    system.hold(t0, p0, hinge_tau, L_rotor)     # inputs held from t0 on (zero-order hold)
    ydot = system.rhs(t, y)                     # y' (size,)

:class:`OdeSystem` is all the integrators (:mod:`gyro_sim.integrators`) ask of a system.
Two implementations of it, same equations, same state layout (:mod:`gyro_sim.dynamics.model`),
same results to round-off (test/dynamics/test_kernel.py):

- :class:`ChainODE`: the numpy reference, :mod:`gyro_sim.dynamics.reference` (eqs 34-54 with a
  composite-inertia matrix); it also fills the outputs (reactions, rotor torques);
- :class:`FastChainODE`: the compiled O(n) articulated-body kernel of
  :mod:`gyro_sim.dynamics.kernel` for `rhs(t, y)` (called through :mod:`gyro_sim.dynamics.entry`:
  its arrays packed in one buffer, four arguments a call instead of 24), the numpy reference
  for outputs.

Backend selection: `make_system(model, backend)` with backend "auto", "numba" or "numpy"
(:data:`BACKENDS`); `gyro_sim.dynamics.kernel.available()` tells whether numba imports.

Imports go one way: simulator -> system -> fast, dynamics, model.
"""
from __future__ import annotations

import warnings
from typing import Protocol

import numpy as np

from gyro_sim.dynamics import reference as dyn
from gyro_sim import jit
from gyro_sim.dynamics import kernel as fast, entry as fast_entry, outputs as fast_outputs
from gyro_sim.dynamics.model import Model, initial_state
from gyro_sim.dynamics.rotations import quat_rates


class OdeSystem(Protocol):
    """The system y' = rhs(t, y) the integrators advance.

    Attributes
    ----------
    size : length of the state vector y.
    quat_index : int array (nq, 4), indices in y of unit quaternions (w, x, y, z),
        world-from-body; nq may be 0. For these blocks rhs returns
        q' = 1/2 (0, omega) (x) q, omega the world-frame angular velocity.

    Methods
    -------
    rhs(t, y) -> (size,) : dy/dt. Assumed expensive; every call is counted in `nfev`.
    project(y) -> None : renormalise the quaternions of y (size,) in place.
    jacobian(t, y) -> (size, size) : optional, d rhs / dy; used by implicit methods (radau),
        which otherwise difference rhs.
    """

    size: int
    quat_index: np.ndarray

    def rhs(self, t: float, y: np.ndarray) -> np.ndarray: ...

    def project(self, y: np.ndarray) -> None: ...


def _same(a, b) -> bool:
    """Two held inputs (None or arrays) with the same values."""
    if a is None or b is None:
        return a is b
    return np.array_equal(a, b)


class ChainODE:
    """The chain as an ODE system for the integrators: y' = f(t, y) with inputs held.

    Inputs (commanded hinge moments, rotor torques) are constant between calls of
    `hold`: the zero-order hold of `Simulator.advance`. Torque-rotor spins are not states:
    p_i(t) = p_i(t0) + (L_i / A_i) (t - t0) (eq 29).
    """

    #: which dynamics this system runs (`make_system`'s backend names)
    backend = "numpy"

    def __init__(self, model: Model):
        self.model = model
        self.data = dyn.Data(model)
        self.size = model.size
        self.quat_index = model.i_quat
        self.hinge_tau: np.ndarray | None = None
        self.L_rotor: np.ndarray | None = None
        self.t0 = 0.0
        self.p0 = model.torque_p0.copy() if len(model.torque_body) else None
        self.nfev = 0
        #: counts the holds whose commanded values (hinge_tau, L_rotor) differ from the last
        self.inputs_version = 0

    def hold(self, t0: float, p0: np.ndarray | None, hinge_tau, L_rotor) -> None:
        if not (_same(hinge_tau, self.hinge_tau) and _same(L_rotor, self.L_rotor)):
            self.inputs_version += 1
        self.t0, self.p0, self.hinge_tau, self.L_rotor = t0, p0, hinge_tau, L_rotor

    @property
    def held(self) -> tuple:
        """The arguments of the last `hold`: (t0, p0, hinge_tau, L_rotor)."""
        return self.t0, self.p0, self.hinge_tau, self.L_rotor

    def spins(self, t: float, y: np.ndarray | None = None) -> np.ndarray | None:
        """Absolute torque-rotor spins p_i(t) (eq 29 integrated over the hold); in a stateful
        model (`Model.stateful`) they are states: those of y (the held p0 without y)."""
        if self.p0 is None:
            return None
        if self.model.stateful:
            return self.p0 if y is None else y[self.model.i_spin]
        if self.L_rotor is None:
            return self.p0
        return self.p0 + (self.L_rotor / self.model.torque_A) * (t - self.t0)

    def rhs(self, t: float, y: np.ndarray, out: dyn.Evaluation | None = None) -> np.ndarray:
        m, d = self.model, self.data
        self.nfev += 1
        p = self.spins(t, y)
        udot = dyn.forward(m, d, t, y, self.hinge_tau, p, self.L_rotor, out)
        u = y[m.i_vel]
        ydot = np.empty(m.size)
        if m.free:
            ydot[m.i_r0] = u[m.col_base]
        if len(m.sph_bodies):
            ydot[m.i_quat] = quat_rates(y[m.i_quat], d.w[m.sph_bodies])  # q' = 1/2 (0, w) (x) q
        ydot[m.i_phi] = u[m.col_hinge]
        ydot[m.i_vel] = udot
        if p is not None:
            ydot[m.i_kappa] = dyn.torque_rotor_rates(m, d, p)  # kappa_i' = p_i - w . e_i (eqs 18-19)
        if m.stateful:  # (29) with the torques applied at this state; the works' powers
            a = d.applied
            ydot[m.i_spin] = (a.rotor_motor + a.rotor_friction) / m.torque_A
            ydot[m.i_work] = a.power()
        return ydot

    def project(self, y: np.ndarray) -> None:
        if len(self.quat_index):
            q = y[self.quat_index]
            y[self.quat_index] = q / np.linalg.norm(q, axis=1, keepdims=True)

    def applied(self, t: float, y: np.ndarray, hinge_tau, L_rotor) -> tuple[np.ndarray, np.ndarray]:
        """A stateful model's motor and friction torques at (t, y) under the commands given, the
        hinges' then the torque rotors' (gyro_sim.dynamics.reference.applied_at); not counted
        in `nfev` and the held inputs kept."""
        return dyn.applied_at(self.model, self.data, t, y, hinge_tau, L_rotor)


_F64 = np.dtype(np.float64)
_empty = np.empty  # FastChainODE.rhs: a global name, one attribute lookup less per call


class FastChainODE:
    """The chain as an ODE system y' = f(t, y) for the integrators, compiled with numba.

    Same interface and results as :class:`ChainODE`: `size`, `quat_index`, `rhs(t, y[, out])`,
    `project(y)`, `hold(t0, p0, hinge_tau, L_rotor)`, `spins(t)`, `nfev`, `model`, `data`.
    `rhs(t, y)` runs the compiled kernel (:func:`gyro_sim.dynamics.kernel.rhs_kernel`) and returns a
    new array (size,); `rhs(t, y, out=ev)` (outputs: reactions, rotor torques) runs the numpy
    reference, which fills `ev` and `data` as ChainODE does.

    Raises ImportError if numba is not available (see `gyro_sim.dynamics.kernel.available`).
    """

    #: which dynamics this system runs (`make_system`'s backend names)
    backend = "numba"

    def __init__(self, model: Model):
        if not fast.available():
            raise ImportError("FastChainODE needs numba; use ChainODE")
        self.model = model
        self._ref = ChainODE(model)  # the numpy path: outputs; also keeps the held inputs
        self.data = self._ref.data
        self.size = model.size
        self.quat_index = model.i_quat
        # the kernel's records, bound together (the workspace's descriptor finds all three):
        # `rhs` passes the descriptor's address, four arguments a call; the compiled loops get
        # the records
        chain = fast.chain_model(model)
        inputs = fast.held_inputs(model, self._ref.t0, self._ref.p0, None, None)
        self._records = (chain, fast.workspace(model, chain, inputs), inputs)
        self._descriptor = self._records[1].descriptor  # nfev: the word the compiled entry counts in
        self._shape = (model.size,)
        self.rhs = self._make_rhs()
        self._i_q0 = int(model.i_quat[0, 0]) if len(model.sph_bodies) else 0
        self._nq = len(model.sph_bodies)
        # outputs: the Simulator's publication kernel (one compiled specialization for both)
        # with everything wanted, no joint states, no scatter
        self._outputs = jit.Direct(fast_outputs.publication_kernel)
        nothing, none = np.empty(0), np.empty(0, dtype=np.int64)
        n = model.n
        self._layout = fast_outputs.layout(model, none, none)  # the model beyond the kernel's records
        self._no_publication = (
            fast_outputs.JointStates(nothing, nothing, nothing),
            fast_outputs.Slots(nothing, np.empty((0, 3, 0), dtype=np.int64), np.empty((0, n, 3), dtype=np.int64),
                               np.empty((0, n, 4), dtype=np.int64), np.empty((0, n, 6), dtype=np.int64)))
        self._scratch = np.empty(fast_outputs.scratch_size(n))

    # --- inputs ------------------------------------------------------------------------------
    def hold(self, t0: float, p0: np.ndarray | None, hinge_tau, L_rotor) -> None:
        """Hold the inputs from t0 on (the zero-order hold of `Simulator.advance`)."""
        self._ref.hold(t0, p0, hinge_tau, L_rotor)
        fast.hold(self._records[2], self.model, t0, p0, hinge_tau, L_rotor)  # in place

    @property
    def inputs_version(self) -> int:
        """Counts the holds whose commanded values differ from the last (ChainODE's)."""
        return self._ref.inputs_version

    @property
    def held(self) -> tuple:
        """The arguments of the last `hold`: (t0, p0, hinge_tau, L_rotor) (ChainODE's)."""
        return self._ref.held

    def applied(self, t: float, y: np.ndarray, hinge_tau, L_rotor) -> tuple[np.ndarray, np.ndarray]:
        """ChainODE.applied (the numpy reference: a step's correction needs it rarely)."""
        return self._ref.applied(t, y, hinge_tau, L_rotor)

    def kernel_arguments(self) -> tuple:
        """The arguments of :func:`gyro_sim.dynamics.kernel.rhs_kernel` after (t, y, out): its
        records (model, data, inputs), the inputs held now, for compiled loops of other modules
        that call the kernel. The same objects from call to call (`hold` writes the new inputs
        into the same arrays)."""
        return self._records

    def records_with_own_inputs(self) -> tuple:
        """The kernel's records (as `kernel_arguments`) with held inputs of their own (held at
        zero; written with gyro_sim.dynamics.outputs.hold) and a workspace for them: for a
        caller that evaluates the same model under other inputs than those held here."""
        chain = self._records[0]
        inputs = fast.held_inputs(self.model)
        return chain, fast.workspace(self.model, chain, inputs), inputs

    def quaternion_block(self) -> tuple[int, int]:
        """(i_q0, nq): the quaternions are y[i_q0 + 4 j : i_q0 + 4 j + 4], j < nq (for
        fast.normalize_quaternions in compiled loops)."""
        return self._i_q0, self._nq

    def spins(self, t: float, y: np.ndarray | None = None) -> np.ndarray | None:
        """Absolute torque-rotor spins p_i(t) (eq 29 integrated over the hold; the states of y
        in a stateful model)."""
        return self._ref.spins(t, y)

    @property
    def hinge_tau(self) -> np.ndarray | None:
        """The commanded hinge moments held now (ChainODE's), or None."""
        return self._ref.hinge_tau

    # --- the ODE -------------------------------------------------------------------------------
    @property
    def nfev(self) -> int:
        """Evaluations of y' counted (rhs, the compiled loops that add
        theirs); settable (the integrators add to it, reset or restore it)."""
        return int(self._descriptor[fast.D_NFEV])

    @nfev.setter
    def nfev(self, value: int) -> None:
        self._descriptor[fast.D_NFEV] = value

    def _make_rhs(self):
        """`rhs(t, y, out=None)`: y' (size,) at (t, y); with `out`, by the numpy reference, which
        also fills `out` and `data`. An instance attribute, a closure over the buffer and the
        entry point (cell reads, not attribute lookups: the call from Python is ~3x the kernel's
        own work on a short chain). y: float64 (size,), contiguous as the integrators pass it,
        goes straight to the compiled entry point of :func:`gyro_sim.dynamics.entry.rhs_entry`
        (compiled or loaded at the first call), which checks its length and stride and counts
        nfev; its dtype and dimensions are checked here, as the entry point converts without
        checking them. Another y (dtype, layout) goes through numba's dispatcher
        (`_rhs_other`): correct too, but it compiles one more specialization of the kernel."""
        size, other = self.size, self._rhs_other
        address = self._descriptor.ctypes.data  # the entry takes the address; `other` (self) keeps it alive

        def first(t, y, ydot, address):
            nonlocal entry
            entry = fast_entry.entry_point()
            if entry is None:  # nothing compiles (NUMBA_DISABLE_JIT): the kernel in Python

                def entry(t, y, ydot, address):
                    ydot[:] = other(t, y, None)

            entry(t, y, ydot, address)

        entry = first

        def rhs(t: float, y: np.ndarray, out: dyn.Evaluation | None = None) -> np.ndarray:
            if out is None and y.dtype is _F64 and y.ndim == 1:
                ydot = _empty(size)
                try:
                    entry(t, y, ydot, address)
                    return ydot
                except ValueError:  # not contiguous, or not of the state's size: not counted
                    pass
            return other(t, y, out)

        rhs.__doc__ = self._make_rhs.__doc__
        return rhs

    def _rhs_other(self, t: float, y, out: dyn.Evaluation | None) -> np.ndarray:
        """rhs for what the compiled entry point does not take: outputs (`out`), another dtype
        or layout of y."""
        self._descriptor[fast.D_NFEV] += 1
        if out is not None:
            return self._ref.rhs(t, y, out)
        if np.shape(y) != self._shape:  # the kernel does not check its indices
            raise ValueError(f"y must have shape ({self.size},), got {np.shape(y)}")
        ydot = _empty(self.size)
        fast.rhs_kernel(float(t), y, ydot, *self._records)
        return ydot

    def outputs(self, t: float, y: np.ndarray) -> dict[str, np.ndarray]:
        """Every output at (t, y) with the inputs held, in one compiled call
        (:func:`gyro_sim.dynamics.outputs.publication_kernel` with everything wanted, no joint
        states: the Simulator's specialization of it);
        new arrays, by name:

        ydot (size,) y' (u' and the torque-rotor angle rates in it), R (n, 3, 3) world_R_body,
        w (n, 3) angular velocities, vO (n, 3) velocities of the joint points, O (n, 3) joint points,
        quat (n, 4) world from body, euler and euler_rate (n, 3), L_speed (nv,) speed-rotor
        motor torques, wrench_force and wrench_moment (n, 3) R^k (eq 40) and L^k (eq 48) in
        body k's frame, inv (fast_outputs.INV_SIZE,) energy, kinetic, potential, jacobi,
        vertical momentum, H_O1 (3), P (3), L about the centre of mass (3). Not counted in nfev.
        """
        m, n = self.model, self.model.n
        out = {"ydot": np.empty(self.size), "R": np.empty((n, 3, 3)), "w": np.empty((n, 3)),
               "vO": np.empty((n, 3)), "O": np.empty((n, 3)), "quat": np.empty((n, 4)),
               "euler": np.empty((n, 3)), "euler_rate": np.empty((n, 3)),
               "L_speed": np.empty(len(m.speed_body)), "wrench_force": np.empty((n, 3)),
               "wrench_moment": np.empty((n, 3)), "inv": np.empty(fast_outputs.INV_SIZE)}
        y = np.ascontiguousarray(y, dtype=np.float64)
        if y.shape != (self.size,):
            raise ValueError(f"y must have shape ({self.size},), got {y.shape}")
        states, slots = self._no_publication
        outputs = fast_outputs.Outputs(*(self._scratch if k == "scratch" else out[k]
                                         for k in fast_outputs.OUTPUT_NAMES))
        self._outputs(float(t), y, out["ydot"], *self._records, self._layout, int(fast_outputs.WANT_ALL), outputs,
                      states, slots)
        return out

    def warm_up(self) -> None:
        """Compile the kernels (or load them from the disk cache) by one evaluation at the
        model's initial state and the outputs; not counted in nfev."""
        y = initial_state(self.model)
        self.rhs(self._ref.t0, y)
        self.project(y)
        self.nfev -= 1
        self.outputs(self._ref.t0, y)

    def project(self, y: np.ndarray) -> None:
        """Renormalise the quaternions of y (size,) in place."""
        if y.shape != (self.size,):
            raise ValueError(f"y must have shape ({self.size},), got {y.shape}")
        if self._nq:
            fast.normalize_quaternions(y, self._i_q0, self._nq)


# --- backend selection ---------------------------------------------------------------------
#: what `make_system` accepts: "auto" (numba if it works, else numpy), "numba", "numpy"
BACKENDS = ("auto", "numba", "numpy")


def heavy_subtree_ratio(model: Model) -> float:
    """The largest ratio of the mass of bodies k+1..n to the mass of body k (on a tree: of a
    child's subtree to its parent's own; a massless body k, which has no inertia of its own to
    lose, left out)."""
    m = model.mass
    if not model.chain:
        sub = dyn.subtree_sum(model, m)
        child = np.flatnonzero((model.parent >= 0))
        child = child[m[model.parent[child]] > 0.0]
        return float(np.max(sub[child] / m[model.parent[child]])) if len(child) else 0.0
    after = np.cumsum(m[::-1])[::-1][1:]
    carriers = m[:-1] > 0.0
    return float(np.max(after[carriers] / m[:-1][carriers])) if np.any(carriers) else 0.0


def make_system(model: Model, backend: str = "auto") -> ChainODE | FastChainODE:
    """The ODE system of `model` for the integrators: FastChainODE or ChainODE.

    backend: "numpy" -> ChainODE; "numba" -> FastChainODE, compiled (or loaded from the disk
    cache) now, so the first integration step does not pay for it; ImportError without numba.
    "auto" -> as "numba" if numba imports and the kernels compile, else ChainODE with a
    warning when numba is there but failed. Heavy tips stay compiled: the kernel's
    elimination is exact to ~1e-14 relative at any mass ratio up to 1e7 either way
    (`gyro_sim.dynamics.kernel.STABLE_ABA_RATIO`, test/dynamics/test_heavy_tip.py).
    """
    if backend not in BACKENDS:
        raise ValueError(f"unknown backend {backend!r}; valid: {', '.join(BACKENDS)}")
    if backend == "numpy" or (backend == "auto" and not fast.available()):
        return ChainODE(model)
    if not fast.available():
        raise ImportError("the numba backend needs numba; use backend 'numpy' or 'auto'")
    try:
        system = FastChainODE(model)
        system.warm_up()
    except jit.NumbaError as exc:
        if backend == "numba":
            raise
        warnings.warn(f"numba backend unavailable ({type(exc).__name__}); using numpy",
                      RuntimeWarning, stacklevel=2)
        return ChainODE(model)
    return system
