"""The chain dynamics compiled with numba: an O(n) articulated-body recursion (docs/theory.md sec. 5).

Kernels only. `rhs_kernel` computes what :meth:`gyro_sim.dynamics.system.ChainODE.rhs` computes
(eqs 34-54 solved for u', the quaternion derivatives, the torque-rotor angle rates of eqs
18-19 and 29), but in one compiled call instead of some hundred numpy calls: the numpy path
costs ~150 us of call overhead per evaluation for any short chain, the kernel a few
microseconds. :class:`gyro_sim.dynamics.system.FastChainODE` is the ODE system built on it
(`records` gives the kernel's records: ChainModel, Workspace, HeldInputs).

Same equations, same velocity basis, state layout and signs as :mod:`gyro_sim.dynamics.model` and
:mod:`gyro_sim.dynamics.reference` (world components; spherical joints move with the relative
angular velocity in world components). Two things differ, neither visible in the results
beyond round-off (test/dynamics/test_kernel.py):

- the spatial quantities of body k are taken about its own joint point O^k (world axes)
  instead of the world origin, so neighbouring bodies differ by the translation s^k only
  and no quantity grows with the distance from the origin;
- the closure rows are solved by the articulated-body algorithm (Featherstone, "Rigid Body
  Dynamics Algorithms", Springer 2008, Table 7.1) instead of forming the composite-inertia
  matrix M (O(n^2)) and solving with it (O(n^3)): the joints are eliminated from the tip to
  the base, then u' is recovered from the base to the tip, O(n). A spherical joint
  transmits no moment (eq 44), so what passes through it is a 3x3 apparent mass.

The articulated inertias are kept exactly symmetric: their antisymmetric round-off grows
geometrically along a chain in this recursion (x2.5 per link on `spherical_chain`, ~1e-5 at
n = 20, O(1) at n = 30 before the fix), while symmetric round-off does not.

Pipeline of one evaluation (`rhs_kernel`), all about O^k in world axes:
    positions    y        -> R^k, s^k, m^k c^k, A^k (world), hinge axes e^k   (eqs 30, 50)
    velocities   y, t     -> w^k, v(O^k), joint biases c^k = S_k' u_k         (eqs 34, 50, 53)
    bias forces  w, v, t  -> spatial inertias, forces at u' = 0               (eqs 29, 31, 36-39, 58)
    ABA          I, p, c  -> u'                                               (eqs 44, 51, 54)
                 (a hinge's armature added to its D_k, its spring's moment to its tau: eq 51a,
                 docs/theory.md section 10; a geared motor's m = J G a to its U_k, m . c^k to
                 its u_k, J G^2 to its D_k, its rotor's gyroscopic moment to the parent's bias
                 force: eq 51b)
    y'           u', w    -> quaternion rates, phi', u', rotor angle rates    (eqs 18-19)

Nothing is allocated per evaluation (test/dynamics/test_kernel_alloc.py): every intermediate lives in
the workspace `workspace(model)` gives, viewed by `block2`/`block3`; 3-vectors, the spherical
elimination (3 x 3 blocks of J, H, M) and the forward sweep's acceleration are scalars, so that
LLVM keeps them in registers. Where a product meets a known zero (a cross-product matrix) it is
left out: the remaining terms are added in the same order, so the results are bit for bit those
of the full products.

Reactions (eqs 40, 48) are outputs and stay on the numpy path (`FastChainODE.rhs(t, y,
out=ev)` delegates to the `ChainODE` it holds).

Small formulas have their numpy home elsewhere and a scalar twin here, written in the same
operations (the kernel inlines it; test/dynamics/test_kernel.py checks the twins against their
homes): `_quat_to_matrix` = :func:`gyro_sim.dynamics.rotations.quat_to_matrix`, `_quat_rate` =
:func:`gyro_sim.dynamics.rotations.quat_rates`, `_rotor_angle_rate` =
:func:`gyro_sim.dynamics.reference.torque_rotor_rates`. They stay in this file because numba's
disk cache only notices edits of the file of the cached function, not of the functions it
calls from other modules (numba docs, "Cache limitations").

`available()` tells whether numba imports. Without numba this module still imports (its
kernels stay plain Python, far too slow to use) and `FastChainODE` raises ImportError.
Compilation: one signature serves every scene (model differences are array contents and
flags), ~12 s of CPU the first time, then ~0.3 s from numba's disk cache, in a directory keyed
on DEPENDENCIES and gyro_sim/jit.py (`gyro_sim.jit.cache_directory`): any edit of them starts
an empty one. The compiled loops of the
other modules do not compile the kernel into themselves: they call it through its C
function (`rhs_call`, the address in flags[FLAG_KERNEL]), and the kernel calls its rare
heavy-subtree path through another (`_heavy`, flags[FLAG_HEAVY]), so each is compiled once.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from pathlib import Path

from gyro_sim import jit
from gyro_sim.dynamics import actuators
from gyro_sim.dynamics.actuators import MAX_SPEED_BAND, STRIBECK_PEAK, STRIBECK_TANH
from gyro_sim.dynamics.model import Model
from gyro_sim.jit import block1, block2, block3, numba

if jit.compiling():
    from gyro_sim.jit import address_of, call_address, vector_at

#: the files the kernels here compile in (the key of their numba cache directory,
#: `gyro_sim.jit.cache_directory`): this one and the actuators' constants it reads
DEPENDENCIES = (Path(__file__), Path(actuators.__file__))

class ChainModel(NamedTuple):
    """The chain's constant arrays as every compiled kernel reads them (numba types a module-level
    NamedTuple of arrays as one record, which caches on disk like its arrays: `chain_model`
    builds it). The one place the model's arrays are named; n bodies, N velocity columns, nt
    torque rotors."""

    #: (n,) bool: body k's own joint has one coordinate, a hinge or a slide (else spherical)
    is_hinge: np.ndarray
    #: (n,) int64: the y index of body k's quaternion (spherical) or of phi_k (hinge)
    qrow: np.ndarray
    #: (n,) int64: the first velocity column of body k's own joint
    own_col: np.ndarray
    #: (n + 1,) int64: body k's columns are col_start[k]:col_start[k + 1] (a free base's
    #: translations belong to body 0)
    col_start: np.ndarray
    #: (n, 3) hinge axes e^k in body k's frame (eq 50)
    hinge_axis: np.ndarray
    #: (n, 3) s^k, the joint point O^{k+1} from O^k in body k's frame
    s: np.ndarray
    #: (n,) masses
    mass: np.ndarray
    #: (n, 3) m^k c^k, first moments about O^k in body k's frame
    first_moment: np.ndarray
    #: (n, 3, 3) inertia operators about O^k (eqs 22, 30)
    inertia: np.ndarray
    #: (n, 3) the constant part of the gyrostatic moments (eq 31)
    lam_speed: np.ndarray
    #: (nt,) int64: the body of each torque rotor
    torque_body: np.ndarray
    #: (nt, 3) torque rotors' axes in their bodies' frames
    torque_axis: np.ndarray
    #: (nt,) axial moments of inertia A_i of the torque rotors (eq 29)
    torque_A: np.ndarray
    #: (FLAGS_SIZE,) int64: see FLAGS_SIZE
    flags: np.ndarray
    #: (7,): moving-base amplitude (3), W = 2 pi f, gravity (3)
    base: np.ndarray
    #: (n,) the hinges' armatures (reflected rotor inertias added to D_k of the elimination;
    #: zero on spherical bodies and on hinges without one)
    armature: np.ndarray
    #: (n, 2) the hinges' springs: stiffness k, reference angle (the moment -k (phi - phi_ref)
    #: is read only with flags[FLAG_SPRINGS])
    spring: np.ndarray
    #: (n, 5) the hinges' servos: gear, b1, b2, force low, high (read only with
    #: flags[FLAG_SERVOS], on the bodies whose gear is not zero; the held drive is in tau)
    servo: np.ndarray
    #: (n, 5) the hinges' geared motors on their parents: J G, J G^2, the rotor's axis a in the
    #: parent's frame (3) (read only with flags[FLAG_MOTORS], on the bodies whose J G^2 is not
    #: zero; docs/theory.md, "The geared motor")
    motor: np.ndarray
    #: (n,) bool: body k's joint of one coordinate (is_hinge) is a slide, a translation d_k along
    #: its axis (docs/theory.md section 12); every "hinge" term above then acts on d_k
    is_slide: np.ndarray
    #: a tree's (flags[FLAG_TREE]): (n,) int64, each body's parent (-1: the base), and `s` holds
    #: each body's joint point O^k from its parent's O in the parent's frame (s^{parent(k),k},
    #: docs/theory.md section 11); (0,) on a chain, whose parent is the body before
    parent: np.ndarray


#: the index of `flags` among ChainModel's fields (its address in a descriptor: D_MODEL + this)
MODEL_FLAGS = list(ChainModel.__annotations__).index("flags")


class Workspace(NamedTuple):
    """What one evaluation writes (`workspace`): the kernel's scratch, and the descriptor by
    which the kernel's C function finds a model, this workspace and held inputs (`describe`,
    the one place it is written): a workspace belongs to the model and inputs it describes."""

    #: the float scratch (`scratch_size`), with a stateful model's actuator parameters in its tail
    work: np.ndarray
    #: (DESCRIPTOR_SIZE,) int64: the arrays' addresses and sizes, and the evaluations counted
    descriptor: np.ndarray


class HeldInputs(NamedTuple):
    """The inputs held from t0 on (the zero-order hold of `Simulator.advance`), as the compiled
    kernels read them (`held_inputs`; written in place by `hold`)."""

    #: (1,): t0, the start of the hold
    t0: np.ndarray
    #: (nt,) torque-rotor spins p_i(t0) (eq 29)
    p0: np.ndarray
    #: (nt,) their rates L_i / A_i
    pdot: np.ndarray
    #: (nt,) the torque rotors' axial torques L_i
    L_rotor: np.ndarray
    #: (N,) generalized forces of the columns (hinge commands, eq 51)
    tau: np.ndarray


# base kinds, as the kernel sees them
BASE_FIXED, BASE_MOVING, BASE_FREE = 0, 1, 2
#: the largest joint: a free base's three translations with the first body's three rotations
MAX_JOINT_DOF = 6
#: columns of a spherical joint (a rotation about O^k)
SPHERICAL_DOF = 3
#: per body, floats of the workspace: R 9, s 3, m c 3, A 9, e 3, w 3, v(O) 3, c 6, I 36, p 6,
#: D^-1 36, lambda 3, lambda' 3
WORK_PER_BODY = 123
#: per velocity column: S 6, U 6, U D^-1 6, u 1
WORK_PER_COLUMN = 19
#: per torque rotor: its spin p_i(t) (eq 29)
WORK_PER_ROTOR = 1
#: fixed scratch of the elimination: a 6 x 6, two 6-vectors, three 3 x 3, the base acceleration 6
WORK_FIXED = 81
#: `_aba` takes the square-root form (`_aba_stable`) when the classic elimination passes on to
#: a body more than this many times its own mass (the subtree's apparent, articulated mass at
#: the joint); below, the formed projection (`_aba_classic`) loses ~10 eps ratio^2 relative
#: (9e-12 at 1e2: test/dynamics/test_heavy_tip.py). Chains whose subtrees all weigh less than this
#: many times their carriers cannot pass on more and skip the check.
STABLE_ABA_RATIO = 100.0
#: flags (`chain_model`, int64): base type, has gravity, has lambda (rotors), i_r0, i_vel,
#: i_kappa, N, then FLAG_HEAVY: the address of the compiled heavy-subtree elimination
#: (`heavy_elimination_address`), 0 for a model whose subtrees all weigh at most STABLE_ABA_RATIO
#: times their carriers (the kernel never takes that path there)
FLAG_HEAVY = 7
#: flags[FLAG_KERNEL]: the address of `rhs_kernel` compiled as a C function (`kernel_address`),
#: which the compiled loops call (`rhs_call`) instead of compiling the kernel into themselves
FLAG_KERNEL = 8
#: flags[FLAG_ACTUATORS]: 1 for a model with state-dependent actuator terms (model.stateful:
#: friction, max_speed, servos), whose spins and works are states at flags[FLAG_I_SPIN],
#: flags[FLAG_I_WORK] and whose parameters sit in the workspace's tail (`workspace`)
FLAG_ACTUATORS, FLAG_I_SPIN, FLAG_I_WORK = 9, 10, 11
#: flags[FLAG_SPRINGS]: 1 for a model with hinge springs, whose moments are added to the
#: generalized forces in the workspace's last N floats (`scratch`)
FLAG_SPRINGS = 12
#: flags[FLAG_SERVOS]: 1 for a model with hinge servos, whose hinges' held tau is the servo's
#: drive gain clip(ctrl) + b0, turned into its moment at the state (`servo_moments`, called by
#: `actuate`: a model with servos is stateful) in the N floats of the workspace before the
#: springs' (`scratch`)
FLAG_SERVOS = 13
#: flags[FLAG_MOTORS]: 1 for a model with geared motors on turning parents, whose per-evaluation
#: terms (m = J G a in world axes, J G^2) sit in 4 n floats before the servos' and springs'
#: (`motor_offset`)
FLAG_MOTORS = 14
#: flags[FLAG_TREE]: 1 for a tree (a body whose parent is not the body before it: ChainModel's
#: `parent`); every loop then goes from parent to child and back (docs/theory.md section 11)
FLAG_TREE = 15
FLAGS_SIZE = 16
#: per actuated axis, floats of the workspace's tail of a stateful model: max_speed (inf: none),
#: coulomb, viscous, static, stribeck_speed (0: no Stribeck term), stick_speed
ACTUATOR_PARAMETERS = 6
#: a workspace's descriptor (int64, `describe`): the addresses of the model's arrays (in
#: ChainModel's order) from D_MODEL, of the scratch at D_WORK, of the held inputs' arrays (in
#: HeldInputs' order) from D_INPUTS; n, N, nt and the scratch's size; the evaluations counted
#: (the compiled entry from Python, gyro_sim.dynamics.entry, counts there)
D_MODEL, D_WORK, D_INPUTS = 0, 21, 22
D_N, D_NCOL, D_NT, D_NWORK, D_NFEV = 27, 28, 29, 30, 31
DESCRIPTOR_SIZE = 32
assert D_WORK - D_MODEL == len(ChainModel.__annotations__) and D_N - D_INPUTS == len(HeldInputs.__annotations__), \
    "the descriptor's layout (D_*) no longer matches the records' fields"


def available() -> bool:
    """True if numba imports, i.e. `gyro_sim.dynamics.system.FastChainODE` can be built."""
    return jit.available()


#: Compiled in nopython mode (`gyro_sim.jit`'s options), cached by the digest of DEPENDENCIES.
#: Without numba's reference counting (`_nrt=False`): these kernels allocate nothing and
#: return no array, and counting every array argument and view at every call (an atomic
#: increment and decrement each) cost ~20 % of an evaluation. Only `_njit_alloc` functions
#: (the rare heavy-tip path) count. The options are given explicitly: numba lets a callee
#: inherit `nrt` and `forceinline` from its caller where they are not set.
_njit = jit.njit_with_dependencies(*DEPENDENCIES, _nrt=False, forceinline=False)
#: `_njit`, always inlined by LLVM into its callers (`forceinline`): the stages of
#: `rhs_kernel` (the elimination `_aba`/`_aba_classic` included) and the small helpers. A call
#: of a stage passed its ~100 words of array structs on the stack (~15 % of an evaluation);
#: inlined, the arrays' shapes and strides are loaded once. Same operations: the results are
#: bit for bit those of the calls.
_njit_inline = jit.njit_with_dependencies(*DEPENDENCIES, _nrt=False, forceinline=True)
#: `_njit` with numba's reference counting, for the functions that allocate (the heavy-tip
#: path of `_aba`, never taken on chains without a subtree STABLE_ABA_RATIO times heavier
#: than its carrier)
_njit_alloc = jit.njit_with_dependencies(*DEPENDENCIES, _nrt=True, forceinline=False)


# --- small fixed-size helpers (inlined by LLVM) ----------------------------------------------
@_njit_inline
def vec_cross(a, b, out):
    """out = a x b (3,); out must not alias a or b."""
    out[0] = a[1] * b[2] - a[2] * b[1]
    out[1] = a[2] * b[0] - a[0] * b[2]
    out[2] = a[0] * b[1] - a[1] * b[0]


@_njit_inline
def vec_cross_add(a, b, out):
    """out += a x b (3,); out must not alias a or b."""
    out[0] += a[1] * b[2] - a[2] * b[1]
    out[1] += a[2] * b[0] - a[0] * b[2]
    out[2] += a[0] * b[1] - a[1] * b[0]


@_njit_inline
def mat_vec(A, x, out):
    """out = A x for A (3, 3), x (3,)."""
    for i in range(3):
        out[i] = A[i, 0] * x[0] + A[i, 1] * x[1] + A[i, 2] * x[2]


@_njit_inline
def dot6(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3] + a[4] * b[4] + a[5] * b[5]


@_njit_inline
def _skew(d, D):
    """D = d x (the matrix of the cross product with d)."""
    D[0, 0], D[0, 1], D[0, 2] = 0.0, -d[2], d[1]
    D[1, 0], D[1, 1], D[1, 2] = d[2], 0.0, -d[0]
    D[2, 0], D[2, 1], D[2, 2] = -d[1], d[0], 0.0


@_njit_inline
def _quat_to_matrix(q0, q1, q2, q3):
    """R (3, 3) of a quaternion (w, x, y, z) as a tuple of its 9 entries, row by row, divided by
    |q|^2 as rotations.quat_to_matrix does (a rotation even for the non-unit quaternions of
    integrator stages)."""
    nn = q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3
    return ((q0 * q0 + q1 * q1 - q2 * q2 - q3 * q3) / nn, 2.0 * (q1 * q2 - q0 * q3) / nn,
            2.0 * (q1 * q3 + q0 * q2) / nn,
            2.0 * (q1 * q2 + q0 * q3) / nn, (q0 * q0 - q1 * q1 + q2 * q2 - q3 * q3) / nn,
            2.0 * (q2 * q3 - q0 * q1) / nn,
            2.0 * (q1 * q3 - q0 * q2) / nn, 2.0 * (q2 * q3 + q0 * q1) / nn,
            (q0 * q0 - q1 * q1 - q2 * q2 + q3 * q3) / nn)


@_njit_inline
def _quat_rate(q0, q1, q2, q3, w0, w1, w2):
    """q' (4-tuple) = 1/2 (0, w) (x) q of a quaternion (w, x, y, z), w in world components
    (rotations.quat_rates in the same operations)."""
    return (-0.5 * (w0 * q1 + w1 * q2 + w2 * q3),
            0.5 * (q0 * w0 + (w1 * q3 - w2 * q2)),
            0.5 * (q0 * w1 + (w2 * q1 - w0 * q3)),
            0.5 * (q0 * w2 + (w0 * q2 - w1 * q1)))


@_njit_inline
def _rotor_angle_rate(p, w0, w1, w2, e0, e1, e2):
    """kappa' = p - w . e (eqs 18-19) of a rotor of spin p about the world axis e on a body
    turning at w (dynamics.torque_rotor_rates in the same operations)."""
    return p - (w0 * e0 + w1 * e1 + w2 * e2)


@_njit_inline
def _friction_torque(w, a, o):
    """-F(w) at relative speed w of the axis whose ACTUATOR_PARAMETERS start at a[o]
    (gyro_sim.dynamics.actuators.AxisLimits.friction in scalar operations)."""
    coulomb, viscous, static, b, stick = a[o + 1], a[o + 2], a[o + 3], a[o + 4], a[o + 5]
    scale = 1.0
    if abs(w) < stick:
        scale = w / stick
        w = stick
    if b > 0.0:
        x = w / b
        f = STRIBECK_PEAK * (static - coulomb) * math.exp(-0.5 * x * x) * x + coulomb * math.tanh(STRIBECK_TANH * x)
    else:
        f = math.copysign(coulomb, w) if w != 0.0 else 0.0
    return -(f + viscous * w) * scale


@_njit_inline
def _speed_cut(torque, w, max_speed):
    """A motor torque with the speed limit applied at relative speed w
    (gyro_sim.dynamics.actuators.AxisLimits.cut in scalar operations)."""
    if torque * w > 0.0 and max_speed < math.inf:
        ramp = (max_speed - abs(w)) / (MAX_SPEED_BAND * max_speed)
        return torque * min(max(ramp, 0.0), 1.0)
    return torque


@_njit_inline
def _inv3_sym(J00, J01, J02, J11, J12, J22):
    """J^-1 of a symmetric positive definite J (3, 3) from its upper triangle (adjugate): its
    upper triangle (d00, d01, d02, d11, d12, d22), the inverse exactly symmetric."""
    c00 = J11 * J22 - J12 * J12
    c01 = J02 * J12 - J01 * J22
    c02 = J01 * J12 - J02 * J11
    c11 = J00 * J22 - J02 * J02
    c12 = J01 * J02 - J00 * J12
    c22 = J00 * J11 - J01 * J01
    inv_det = 1.0 / (J00 * c00 + J01 * c01 + J02 * c02)
    return c00 * inv_det, c01 * inv_det, c02 * inv_det, c11 * inv_det, c12 * inv_det, c22 * inv_det


@_njit
def _spd_inverse(D, nk):
    """In-place inverse of the symmetric positive definite D[:nk, :nk], nk <= MAX_JOINT_DOF
    (Gauss-Jordan; SPD needs no pivoting)."""
    for p in range(nk):
        piv = 1.0 / D[p, p]
        D[p, p] = 1.0
        for j in range(nk):
            D[p, j] *= piv
        for i in range(nk):
            if i != p:
                f = D[i, p]
                D[i, p] = 0.0
                for j in range(nk):
                    D[i, j] -= f * D[p, j]


@_njit
def _joint_projection(S, U, D, W, j0, nk, armature):
    """The joint's articulated projection from U = I^A S (rows j0 .. j0+nk): D = S^T U (plus
    a hinge's armature, its own diagonal of the mass matrix), its inverse in place, and
    W = U D^-1 (what both forms of the elimination need)."""
    for a in range(nk):
        for b in range(a, nk):
            D[a, b] = dot6(S[j0 + a], U[j0 + b])
            D[b, a] = D[a, b]
    if nk == 1:
        D[0, 0] += armature
    _spd_inverse(D, nk)
    for a in range(nk):
        for r in range(6):
            acc = 0.0
            for b in range(nk):
                acc += U[j0 + b, r] * D[b, a]
            W[j0 + a, r] = acc


@_njit
def _shift_inertia(I, d, out, Dx, T, G):
    """out += I moved from point P to Q = P - d (world axes): X^T I X, X = [[1, 0], [-d x, 1]].

    With I = [[J, H], [H^T, M]] about P: H_Q = H + d x M, J_Q = J - G - G^T - (d x M) d x with
    G = H d x, M_Q = M. Only the upper triangles are computed: out stays exactly symmetric.
    Dx, T, G: (3, 3) scratch.
    """
    _skew(d, Dx)
    for a in range(3):
        for b in range(3):
            T[a, b] = Dx[a, 0] * I[3, 3 + b] + Dx[a, 1] * I[4, 3 + b] + Dx[a, 2] * I[5, 3 + b]
            G[a, b] = I[a, 3] * Dx[0, b] + I[a, 4] * Dx[1, b] + I[a, 5] * Dx[2, b]
    for a in range(3):
        for b in range(3):
            HQ = I[a, 3 + b] + T[a, b]
            out[a, 3 + b] += HQ
            out[3 + b, a] += HQ
        for b in range(a, 3):
            JQ = I[a, b] - G[a, b] - G[b, a] - (T[a, 0] * Dx[0, b] + T[a, 1] * Dx[1, b] + T[a, 2] * Dx[2, b])
            out[a, b] += JQ
            out[3 + a, 3 + b] += I[3 + a, 3 + b]
            if b != a:
                out[b, a] += JQ
                out[3 + b, 3 + a] += I[3 + a, 3 + b]



@_njit_inline
def _shift_mass(m00, m01, m02, m11, m12, m22, d0, d1, d2, IA, kp):
    """IA[kp] += [[0, 0], [0, Ma]] moved from P to Q = P - d: the apparent mass Ma (symmetric,
    its upper triangle) passed through a spherical joint at P. With T = d x Ma:
    H_Q = T, J_Q = -T d x, M_Q = Ma (the products with the zeros of d x left out)."""
    # T = d x Ma, d x = [[0, -d2, d1], [d2, 0, -d0], [-d1, d0, 0]]
    t00 = -d2 * m01 + d1 * m02
    t01 = -d2 * m11 + d1 * m12
    t02 = -d2 * m12 + d1 * m22
    t10 = d2 * m00 + -d0 * m02
    t11 = d2 * m01 + -d0 * m12
    t12 = d2 * m02 + -d0 * m22
    t20 = -d1 * m00 + d0 * m01
    t21 = -d1 * m01 + d0 * m11
    t22 = -d1 * m02 + d0 * m12
    # H_Q (upper right) and H_Q^T (lower left)
    IA[kp, 0, 3] += t00
    IA[kp, 0, 4] += t01
    IA[kp, 0, 5] += t02
    IA[kp, 1, 3] += t10
    IA[kp, 1, 4] += t11
    IA[kp, 1, 5] += t12
    IA[kp, 2, 3] += t20
    IA[kp, 2, 4] += t21
    IA[kp, 2, 5] += t22
    IA[kp, 3, 0] += t00
    IA[kp, 4, 0] += t01
    IA[kp, 5, 0] += t02
    IA[kp, 3, 1] += t10
    IA[kp, 4, 1] += t11
    IA[kp, 5, 1] += t12
    IA[kp, 3, 2] += t20
    IA[kp, 4, 2] += t21
    IA[kp, 5, 2] += t22
    # J_Q = -T d x: column b of d x is (0, d2, -d1), (-d2, 0, d0), (d1, -d0, 0)
    j00 = -(t01 * d2 + t02 * -d1)
    j01 = -(t00 * -d2 + t02 * d0)
    j02 = -(t00 * d1 + t01 * -d0)
    j11 = -(t10 * -d2 + t12 * d0)
    j12 = -(t10 * d1 + t11 * -d0)
    j22 = -(t20 * d1 + t21 * -d0)
    IA[kp, 0, 0] += j00
    IA[kp, 0, 1] += j01
    IA[kp, 0, 2] += j02
    IA[kp, 1, 1] += j11
    IA[kp, 1, 2] += j12
    IA[kp, 2, 2] += j22
    IA[kp, 1, 0] += j01
    IA[kp, 2, 0] += j02
    IA[kp, 2, 1] += j12
    # M_Q = Ma
    IA[kp, 3, 3] += m00
    IA[kp, 3, 4] += m01
    IA[kp, 3, 5] += m02
    IA[kp, 4, 4] += m11
    IA[kp, 4, 5] += m12
    IA[kp, 5, 5] += m22
    IA[kp, 4, 3] += m01
    IA[kp, 5, 3] += m02
    IA[kp, 5, 4] += m12


# --- stages -----------------------------------------------------------------------------------
@_njit_inline
def body_positions(y, model, R, s_w, hk, Aw, e_w):
    """World components of each body's constants: R^k (quaternion, or eq 50 for a hinge),
    s^k, h^k = m^k c^k, the inertia A^k about O^k (eq 30) and the hinge or slide axis e^k.
    A slide keeps its parent's orientation and moves O^k by e^k d_k: s_w[k - 1] leaves as the
    whole offset O^k - O^{k-1} (section 12; a first body's slide moves O^1, which nothing here
    reads: its velocity is `body_velocities`', its point the outputs'). On a tree (ChainModel's
    `parent`) s_w[k] is body k's whole offset O^k - O^{parent(k)} (from the base's point for a
    body on the base), R^{parent(k)} s^{parent(k),k} plus a slide's e^k d_k."""
    is_hinge, is_slide, qrow, hinge_axis, s, first_moment, inertia = (
        model.is_hinge, model.is_slide, model.qrow, model.hinge_axis, model.s, model.first_moment, model.inertia)
    n = s.shape[0]
    tree = model.parent.shape[0] != 0
    for k in range(n):
        i = qrow[k]
        kp = model.parent[k] if tree else k - 1
        if tree:  # s_w[k] = O^k - O^{parent}: the parent's R, or the world's on the base
            for a in range(3):
                s_w[k, a] = ((R[kp, a, 0] * s[k, 0] + R[kp, a, 1] * s[k, 1] + R[kp, a, 2] * s[k, 2]) if kp >= 0
                             else s[k, a])
        if is_slide[k]:
            for a in range(3):
                for b in range(3):
                    R[k, a, b] = R[kp, a, b] if kp >= 0 else (1.0 if a == b else 0.0)
            e0, e1, e2 = hinge_axis[k, 0], hinge_axis[k, 1], hinge_axis[k, 2]
            d = y[i]
            for a in range(3):
                e_w[k, a] = R[k, a, 0] * e0 + R[k, a, 1] * e1 + R[k, a, 2] * e2
                if tree:
                    s_w[k, a] += e_w[k, a] * d
                elif k > 0:
                    s_w[k - 1, a] += e_w[k, a] * d
        elif is_hinge[k]:
            # (50): body k is its parent turned by phi_k about e^k: Rrel = 1 + sin K + (1 - cos) K^2,
            # K = e x = [[0, -e2, e1], [e2, 0, -e0], [-e1, e0, 0]]; Rrel is held in R[k]
            phi = y[i]
            sp, cp = math.sin(phi), 1.0 - math.cos(phi)
            e0, e1, e2 = hinge_axis[k, 0], hinge_axis[k, 1], hinge_axis[k, 2]
            R[k, 0, 0] = 1.0 + sp * 0.0 + cp * (-e2 * e2 + e1 * -e1)
            R[k, 0, 1] = 0.0 + sp * -e2 + cp * (e1 * e0)
            R[k, 0, 2] = 0.0 + sp * e1 + cp * (-e2 * -e0)
            R[k, 1, 0] = 0.0 + sp * e2 + cp * (-e0 * -e1)
            R[k, 1, 1] = 1.0 + sp * 0.0 + cp * (e2 * -e2 + -e0 * e0)
            R[k, 1, 2] = 0.0 + sp * -e0 + cp * (e2 * e1)
            R[k, 2, 0] = 0.0 + sp * -e1 + cp * (e0 * e2)
            R[k, 2, 1] = 0.0 + sp * e0 + cp * (-e1 * -e2)
            R[k, 2, 2] = 1.0 + sp * 0.0 + cp * (-e1 * e1 + e0 * -e0)
            if kp >= 0:
                # R^k = R^{k-1} Rrel, a column at a time (Rrel's column read before it is replaced)
                for b in range(3):
                    x0, x1, x2 = R[k, 0, b], R[k, 1, b], R[k, 2, b]
                    for a in range(3):
                        R[k, a, b] = R[kp, a, 0] * x0 + R[kp, a, 1] * x1 + R[kp, a, 2] * x2
            for a in range(3):
                e_w[k, a] = R[k, a, 0] * e0 + R[k, a, 1] * e1 + R[k, a, 2] * e2
        else:
            (R[k, 0, 0], R[k, 0, 1], R[k, 0, 2], R[k, 1, 0], R[k, 1, 1], R[k, 1, 2],
             R[k, 2, 0], R[k, 2, 1], R[k, 2, 2]) = _quat_to_matrix(y[i], y[i + 1], y[i + 2], y[i + 3])
            e_w[k, 0] = 0.0
            e_w[k, 1] = 0.0
            e_w[k, 2] = 0.0
        if tree:  # s_w[k] is set above
            for a in range(3):
                r0, r1, r2 = R[k, a, 0], R[k, a, 1], R[k, a, 2]
                hk[k, a] = r0 * first_moment[k, 0] + r1 * first_moment[k, 1] + r2 * first_moment[k, 2]
        else:
            for a in range(3):
                r0, r1, r2 = R[k, a, 0], R[k, a, 1], R[k, a, 2]
                s_w[k, a] = r0 * s[k, 0] + r1 * s[k, 1] + r2 * s[k, 2]
                hk[k, a] = r0 * first_moment[k, 0] + r1 * first_moment[k, 1] + r2 * first_moment[k, 2]
        # R A R^T, exactly symmetric (see the module docstring): row a of R A, then row a of the
        # upper triangle
        for a in range(3):
            r0, r1, r2 = R[k, a, 0], R[k, a, 1], R[k, a, 2]
            k0 = r0 * inertia[k, 0, 0] + r1 * inertia[k, 1, 0] + r2 * inertia[k, 2, 0]
            k1 = r0 * inertia[k, 0, 1] + r1 * inertia[k, 1, 1] + r2 * inertia[k, 2, 1]
            k2 = r0 * inertia[k, 0, 2] + r1 * inertia[k, 1, 2] + r2 * inertia[k, 2, 2]
            for b in range(a, 3):
                Aw[k, a, b] = k0 * R[k, b, 0] + k1 * R[k, b, 1] + k2 * R[k, b, 2]
                Aw[k, b, a] = Aw[k, a, b]


@_njit_inline
def body_velocities(t, y, model, s_w, e_w, w, vO, c):
    """w^k (prefix sums of the joint rates, eqs 50, 53), v(O^k) (eq 34) and the joint bias
    accelerations c^k = S_k' u_k about O^k (dyn.bias_accelerations are their prefix sums about
    the origin):

        spherical joint (world-component axes do not turn): c = (0, v(O^k) x w_rel)
        hinge, (e^k)' = w^{k-1} x e^k: c = (w^{k-1} x e^k phi', v(O^k) x e^k phi')
        slide, S = (0, e^k): no rotation, v(O^k) gains e^k d_k', c = (0, w^{k-1} x e^k d_k')
    """
    is_hinge, is_slide, own_col, flags, base = model.is_hinge, model.is_slide, model.own_col, model.flags, model.base
    base_type, i_vel, base_amplitude, base_omega = flags[0], flags[4], base[0:3], base[3]
    n = s_w.shape[0]
    tree = model.parent.shape[0] != 0
    wp0, wp1, wp2 = 0.0, 0.0, 0.0  # w^{k-1}
    for k in range(n):
        kp = k - 1
        ko = k - 1  # the row of s_w that holds O^k - O^{parent}
        if tree:
            kp, ko = model.parent[k], k
            if kp >= 0:
                wp0, wp1, wp2 = w[kp, 0], w[kp, 1], w[kp, 2]
            else:
                wp0, wp1, wp2 = 0.0, 0.0, 0.0
        if kp < 0:
            # v(O^1): free base (a state), moving base (a W cos(W t)) or fixed
            if base_type == BASE_FREE:
                for a in range(3):
                    vO[k, a] = y[i_vel + a]
            elif base_type == BASE_MOVING:
                cw = base_omega * math.cos(base_omega * t)
                for a in range(3):
                    vO[k, a] = base_amplitude[a] * cw
            else:
                for a in range(3):
                    vO[k, a] = 0.0
        else:
            # (34): v0^k = v0^{k-1} + w^{k-1} x s^{k-1}
            s0, s1, s2 = s_w[ko, 0], s_w[ko, 1], s_w[ko, 2]
            vO[k, 0] = (wp1 * s2 - wp2 * s1) + vO[kp, 0]
            vO[k, 1] = (wp2 * s0 - wp0 * s2) + vO[kp, 1]
            vO[k, 2] = (wp0 * s1 - wp1 * s0) + vO[kp, 2]
        j = i_vel + own_col[k]
        slide = is_slide[k]
        if slide:
            dd = y[j]
            t0_, t1_, t2_ = e_w[k, 0] * dd, e_w[k, 1] * dd, e_w[k, 2] * dd
            vO[k, 0] += t0_
            vO[k, 1] += t1_
            vO[k, 2] += t2_
            wr0, wr1, wr2 = 0.0, 0.0, 0.0
            c[k, 0] = 0.0
            c[k, 1] = 0.0
            c[k, 2] = 0.0
            c[k, 3] = wp1 * t2_ - wp2 * t1_
            c[k, 4] = wp2 * t0_ - wp0 * t2_
            c[k, 5] = wp0 * t1_ - wp1 * t0_
        elif is_hinge[k]:
            ph = y[j]
            # (50): e^k phi_k'
            wr0, wr1, wr2 = e_w[k, 0] * ph, e_w[k, 1] * ph, e_w[k, 2] * ph
            c[k, 0] = wp1 * wr2 - wp2 * wr1
            c[k, 1] = wp2 * wr0 - wp0 * wr2
            c[k, 2] = wp0 * wr1 - wp1 * wr0
        else:
            wr0, wr1, wr2 = y[j], y[j + 1], y[j + 2]
            c[k, 0] = 0.0
            c[k, 1] = 0.0
            c[k, 2] = 0.0
        wp0, wp1, wp2 = wp0 + wr0, wp1 + wr1, wp2 + wr2
        w[k, 0], w[k, 1], w[k, 2] = wp0, wp1, wp2
        if not slide:
            v0, v1, v2 = vO[k, 0], vO[k, 1], vO[k, 2]
            c[k, 3] = v1 * wr2 - v2 * wr1
            c[k, 4] = v2 * wr0 - v0 * wr2
            c[k, 5] = v0 * wr1 - v1 * wr0


@_njit_inline
def _spatial_inertia(k, m, h0, h1, h2, Aw, I6):
    """I6[k] = [[A, h x], [(h x)^T, m 1]]: body k's spatial inertia about O^k (world axes) from
    its inertia A (Aw[k]), first moment h = m c and mass m."""
    for a in range(3):
        for b in range(3):
            I6[k, a, b] = Aw[k, a, b]
            I6[k, 3 + a, 3 + b] = m if a == b else 0.0
    I6[k, 0, 3], I6[k, 0, 4], I6[k, 0, 5] = 0.0, -h2, h1
    I6[k, 1, 3], I6[k, 1, 4], I6[k, 1, 5] = h2, 0.0, -h0
    I6[k, 2, 3], I6[k, 2, 4], I6[k, 2, 5] = -h1, h0, 0.0
    for a in range(3):
        for b in range(3):
            I6[k, 3 + a, b] = I6[k, b, 3 + a]


@_njit_inline
def bias_forces(model, R, hk, Aw, w, vO, p, L_rotor, lam_b, dlam_b, I6, pb):
    """Spatial inertias I6 (n, 6, 6) and body forces at zero acceleration pb (n, 6) about O^k,
    as dyn.body_forces with acc = 0 (eqs 36-39, 58; h = m c in world components):

        I = [[A, h x], [(h x)^T, m 1]],  pb = V x* (I V + (lambda, 0)) + (lambda', 0) - (h x g, m g)

    lambda^k = R (lam_speed^k + sum_i A_i p_i e_i) (eq 31), lambda' = R sum_i L_i e_i (eq 29).
    lam_b, dlam_b (n, 3): scratch.
    """
    mass, lam_speed, torque_body, torque_axis, torque_A = (model.mass, model.lam_speed, model.torque_body,
                                                           model.torque_axis, model.torque_A)
    has_lam, has_gravity, gravity = model.flags[2] != 0, model.flags[1] != 0, model.base[4:7]
    n = mass.shape[0]
    if has_lam:
        for k in range(n):
            for a in range(3):
                lam_b[k, a] = lam_speed[k, a]
                dlam_b[k, a] = 0.0
        for i in range(torque_body.shape[0]):
            k = torque_body[i]
            for a in range(3):
                lam_b[k, a] += torque_A[i] * p[i] * torque_axis[i, a]
                dlam_b[k, a] += L_rotor[i] * torque_axis[i, a]
    g0, g1, g2 = gravity[0], gravity[1], gravity[2]
    for k in range(n):
        m = mass[k]
        h0, h1, h2 = hk[k, 0], hk[k, 1], hk[k, 2]
        w0, w1, w2 = w[k, 0], w[k, 1], w[k, 2]
        v0, v1, v2 = vO[k, 0], vO[k, 1], vO[k, 2]
        _spatial_inertia(k, m, h0, h1, h2, Aw, I6)
        # momentum about O^k: (A w + h x v + lambda, m v + w x h)
        ma0 = (Aw[k, 0, 0] * w0 + Aw[k, 0, 1] * w1 + Aw[k, 0, 2] * w2) + (h1 * v2 - h2 * v1)
        ma1 = (Aw[k, 1, 0] * w0 + Aw[k, 1, 1] * w1 + Aw[k, 1, 2] * w2) + (h2 * v0 - h0 * v2)
        ma2 = (Aw[k, 2, 0] * w0 + Aw[k, 2, 1] * w1 + Aw[k, 2, 2] * w2) + (h0 * v1 - h1 * v0)
        if has_lam:
            l0, l1, l2 = lam_b[k, 0], lam_b[k, 1], lam_b[k, 2]
            ma0 += R[k, 0, 0] * l0 + R[k, 0, 1] * l1 + R[k, 0, 2] * l2
            ma1 += R[k, 1, 0] * l0 + R[k, 1, 1] * l1 + R[k, 1, 2] * l2
            ma2 += R[k, 2, 0] * l0 + R[k, 2, 1] * l1 + R[k, 2, 2] * l2
        ml0 = (w1 * h2 - w2 * h1) + m * v0
        ml1 = (w2 * h0 - w0 * h2) + m * v1
        ml2 = (w0 * h1 - w1 * h0) + m * v2
        # V x* momentum = (w x ang + v x lin, w x lin)
        f0 = (w1 * ma2 - w2 * ma1) + (v1 * ml2 - v2 * ml1)
        f1 = (w2 * ma0 - w0 * ma2) + (v2 * ml0 - v0 * ml2)
        f2 = (w0 * ma1 - w1 * ma0) + (v0 * ml1 - v1 * ml0)
        f3 = w1 * ml2 - w2 * ml1
        f4 = w2 * ml0 - w0 * ml2
        f5 = w0 * ml1 - w1 * ml0
        if has_lam:
            l0, l1, l2 = dlam_b[k, 0], dlam_b[k, 1], dlam_b[k, 2]
            f0 += R[k, 0, 0] * l0 + R[k, 0, 1] * l1 + R[k, 0, 2] * l2
            f1 += R[k, 1, 0] * l0 + R[k, 1, 1] * l1 + R[k, 1, 2] * l2
            f2 += R[k, 2, 0] * l0 + R[k, 2, 1] * l1 + R[k, 2, 2] * l2
        if has_gravity:
            f0 -= h1 * g2 - h2 * g1
            f1 -= h2 * g0 - h0 * g2
            f2 -= h0 * g1 - h1 * g0
            f3 -= m * g0
            f4 -= m * g1
            f5 -= m * g2
        pb[k, 0], pb[k, 1], pb[k, 2], pb[k, 3], pb[k, 4], pb[k, 5] = f0, f1, f2, f3, f4, f5


@_njit_inline
def _joint_columns(is_hinge, is_slide, own_col, base_type, e_w, S):
    """Unit motions S_j (N, 6) of the velocity columns about their body's O^k (dyn.joint_columns
    moved there): spherical (e_i, 0), hinge (e^k, 0), slide (0, e^k), free base (0, e_i)."""
    S[:, :] = 0.0
    if base_type == BASE_FREE:
        for a in range(3):
            S[a, 3 + a] = 1.0
    for k in range(e_w.shape[0]):
        j = own_col[k]
        if is_slide[k]:
            for a in range(3):
                S[j, 3 + a] = e_w[k, a]
        elif is_hinge[k]:
            for a in range(3):
                S[j, a] = e_w[k, a]
        else:
            for a in range(3):
                S[j + a, a] = 1.0


@_njit
def _chol_upper6(I, F):
    """F (6, 6) upper triangular with F^T F = I, I (6, 6) symmetric positive semidefinite
    (Cholesky; a pivot <= 0, a direction without inertia, leaves its row zero)."""
    for i in range(6):
        for j in range(6):
            F[i, j] = 0.0
    for i in range(6):
        d = I[i, i]
        for p in range(i):
            d -= F[p, i] * F[p, i]
        if d <= 0.0:
            continue
        r = math.sqrt(d)
        F[i, i] = r
        for j in range(i + 1, 6):
            acc = I[i, j]
            for p in range(i):
                acc -= F[p, i] * F[p, j]
            F[i, j] = acc / r


@_njit
def _householder_qr6(A, m, v):
    """A[:m, :6] -> its R factor in A[:6, :6] (upper triangular; rows below set to zero):
    Householder QR, A^T A unchanged to round-off (Golub & Van Loan, Alg. 5.2.1). v (m,): scratch."""
    for j in range(6):
        if j >= m:
            break
        nrm = 0.0
        for i in range(j, m):
            nrm += A[i, j] * A[i, j]
        nrm = math.sqrt(nrm)
        if nrm == 0.0:
            continue
        alpha = -nrm if A[j, j] >= 0.0 else nrm
        vv = 0.0
        for i in range(j, m):
            v[i] = A[i, j]
        v[j] -= alpha
        for i in range(j, m):
            vv += v[i] * v[i]
        A[j, j] = alpha
        for i in range(j + 1, m):
            A[i, j] = 0.0
        if vv == 0.0:
            continue
        for q in range(j + 1, 6):
            acc = 0.0
            for i in range(j, m):
                acc += v[i] * A[i, q]
            f = 2.0 * acc / vv
            for i in range(j, m):
                A[i, q] -= f * v[i]
    for i in range(6, m):
        for q in range(6):
            A[i, q] = 0.0


@_njit
def _hinge_reflector(e, H):
    """H (3, 3) symmetric orthogonal with H e = sigma e_1; returns sigma = +-1 (the Householder
    reflector of e, v = e + sign(e_0) e_1, stable for any unit e)."""
    sg = 1.0 if e[0] >= 0.0 else -1.0
    v0, v1, v2 = e[0] + sg, e[1], e[2]
    f = 2.0 / (v0 * v0 + v1 * v1 + v2 * v2)
    v = (v0, v1, v2)
    for a in range(3):
        for b in range(3):
            H[a, b] = (1.0 if a == b else 0.0) - f * v[a] * v[b]
    return -sg


class Elimination(NamedTuple):
    """The arrays of one articulated-body elimination (`_aba`), views of a workspace: the joint
    columns S (N, 6), the bodies' inertias IA (n, 6, 6) and bias forces pA (n, 6) (overwritten),
    the joint bias accelerations c (n, 6), the base's acceleration a_base (6,), the joint
    offsets s_w (n, 3); U, W (N, 6), u (N,), Dinv (n, 6, 6), Ia (6, 6), pa (6,), Dx, T, G (3, 3),
    x (6,): scratch; armature (n,): each hinge's, added to its D (zero elsewhere); motor (n, 4) or
    (0, 4) without motors: each hinge's geared motor, m = J G a (world axes, a the rotor's axis)
    and J G^2 (zero rows: none; `motor_axes`). The eliminations take a tree's parents apart
    (`parent`: (n,) int64, -1 on the base, s_w[k] then O^k - O^{parent(k)}; (0,) on a chain,
    whose parent is k - 1 and s_w[k - 1] = O^k - O^{k-1})."""

    S: np.ndarray
    IA: np.ndarray
    pA: np.ndarray
    c: np.ndarray
    a_base: np.ndarray
    s_w: np.ndarray
    U: np.ndarray
    W: np.ndarray
    u: np.ndarray
    Dinv: np.ndarray
    Ia: np.ndarray
    pa: np.ndarray
    Dx: np.ndarray
    T: np.ndarray
    G: np.ndarray
    x: np.ndarray
    armature: np.ndarray
    motor: np.ndarray


@_njit_inline
def _motor_column(S, U, u, c, motor, k, j0):
    """A geared motor in hinge k's elimination (eq 51b: the row gains m . w^{k-1}' + J G^2
    phi_k''): U' = U + (m, 0), u' = u + m . c^k (the parent's angular acceleration is that of
    body k before its joint, less c^k's); returns what D = S^T U' must gain to be S^T U + J G^2."""
    m0, m1, m2 = motor[k, 0], motor[k, 1], motor[k, 2]
    U[j0, 0] += m0
    U[j0, 1] += m1
    U[j0, 2] += m2
    u[j0] += m0 * c[k, 0] + m1 * c[k, 1] + m2 * c[k, 2]
    return motor[k, 3] - (m0 * S[j0, 0] + m1 * S[j0, 1] + m2 * S[j0, 2])


@_njit_inline
def _aba_classic(is_hinge, col_start, e, tau, udot, parent):
    """`_aba` as Featherstone writes it, the articulated inertias formed: I^a = I^A - U D^-1 U^T.
    Fast, and exact to round-off while no subtree is much heavier than its carrier (see
    STABLE_ABA_RATIO); IA leaves as the articulated inertias. Returns the largest apparent mass
    passed on to a body over that body's own mass.

    Articulated-body algorithm: u' (N,) of the closure rows S_j . F_subtree(k(j)) = tau_j
    (eqs 44, 51, 54; Featherstone 2008, Table 7.1), about each body's O^k in world axes.

    IA (n, 6, 6) and pA (n, 6) enter as the bodies' own inertias and bias forces and leave as
    the articulated ones. c (n, 6): joint bias accelerations; a_base (6,): acceleration of the
    base at O^1; tau (N,): generalized forces of the columns. U, W (N, 6), u (N,),
    Dinv (n, 6, 6), Ia (6, 6), pa (6,), Dx, T, G (3, 3), x (6,): scratch. A spherical joint
    (S = (1, 0)) is eliminated in closed form, in scalars: D = J, and only the apparent mass
    M - H^T J^-1 H passes to the parent.
    """
    S, IA, pA, c, a_base, s_w, U, W, u, Dinv, Ia, pa, Dx, T, G, x, armature, motor = e
    n = IA.shape[0]
    tree = parent.shape[0] != 0
    worst = 0.0  # largest apparent mass passed on / the carrier's own mass
    # backward: I^a = I^A - U D^-1 U^T, p^a = p^A + I^a c + U D^-1 u, to the parent's O^{k-1}
    # (a tree's: each child's to its parent's, O^{parent(k)} = O^k - s_w[k])
    for k in range(n - 1, -1, -1):
        j0, j1 = col_start[k], col_start[k + 1]
        nk = j1 - j0
        kp, ko = (parent[k], k) if tree else (k - 1, k - 1)
        if nk == SPHERICAL_DOF and not is_hinge[k]:
            # D^-1 = J^-1, I^A = [[J, H], [H^T, M]]
            d00, d01, d02, d11, d12, d22 = _inv3_sym(IA[k, 0, 0], IA[k, 0, 1], IA[k, 0, 2],
                                                     IA[k, 1, 1], IA[k, 1, 2], IA[k, 2, 2])
            Dinv[k, 0, 0], Dinv[k, 0, 1], Dinv[k, 0, 2] = d00, d01, d02
            Dinv[k, 1, 0], Dinv[k, 1, 1], Dinv[k, 1, 2] = d01, d11, d12
            Dinv[k, 2, 0], Dinv[k, 2, 1], Dinv[k, 2, 2] = d02, d12, d22
            u0 = tau[j0] - pA[k, 0]
            u1 = tau[j0 + 1] - pA[k, 1]
            u2 = tau[j0 + 2] - pA[k, 2]
            u[j0], u[j0 + 1], u[j0 + 2] = u0, u1, u2
            if kp < 0:
                continue
            h00, h01, h02 = IA[k, 0, 3], IA[k, 0, 4], IA[k, 0, 5]
            h10, h11, h12 = IA[k, 1, 3], IA[k, 1, 4], IA[k, 1, 5]
            h20, h21, h22 = IA[k, 2, 3], IA[k, 2, 4], IA[k, 2, 5]
            # G = J^-1 H
            g00 = d00 * h00 + d01 * h10 + d02 * h20
            g01 = d00 * h01 + d01 * h11 + d02 * h21
            g02 = d00 * h02 + d01 * h12 + d02 * h22
            g10 = d01 * h00 + d11 * h10 + d12 * h20
            g11 = d01 * h01 + d11 * h11 + d12 * h21
            g12 = d01 * h02 + d11 * h12 + d12 * h22
            g20 = d02 * h00 + d12 * h10 + d22 * h20
            g21 = d02 * h01 + d12 * h11 + d22 * h21
            g22 = d02 * h02 + d12 * h12 + d22 * h22
            # Ma = M - H^T J^-1 H (upper triangle)
            m00 = IA[k, 3, 3] - (h00 * g00 + h10 * g10 + h20 * g20)
            m01 = IA[k, 3, 4] - (h00 * g01 + h10 * g11 + h20 * g21)
            m02 = IA[k, 3, 5] - (h00 * g02 + h10 * g12 + h20 * g22)
            m11 = IA[k, 4, 4] - (h01 * g01 + h11 * g11 + h21 * g21)
            m12 = IA[k, 4, 5] - (h01 * g02 + h11 * g12 + h21 * g22)
            m22 = IA[k, 5, 5] - (h02 * g02 + h12 * g12 + h22 * g22)
            # p^a = (tau, p^A_lin + Ma c_lin + (J^-1 H)^T u)
            c3, c4, c5 = c[k, 3], c[k, 4], c[k, 5]
            pl0 = pA[k, 3] + (m00 * c3 + m01 * c4 + m02 * c5) + (g00 * u0 + g10 * u1 + g20 * u2)
            pl1 = pA[k, 4] + (m01 * c3 + m11 * c4 + m12 * c5) + (g01 * u0 + g11 * u1 + g21 * u2)
            pl2 = pA[k, 5] + (m02 * c3 + m12 * c4 + m22 * c5) + (g02 * u0 + g12 * u1 + g22 * u2)
            ratio = (m00 + m11 + m22) / (3.0 * IA[kp, 3, 3]) if IA[kp, 3, 3] > 0.0 else 0.0
            if ratio > worst:
                worst = ratio
            s0, s1, s2 = s_w[ko, 0], s_w[ko, 1], s_w[ko, 2]
            _shift_mass(m00, m01, m02, m11, m12, m22, s0, s1, s2, IA, kp)
            # forces to O^{k-1} = O^k - s^{k-1}: (n + s x f, f)
            pA[kp, 0] = (pA[kp, 0] + (s1 * pl2 - s2 * pl1)) + tau[j0]
            pA[kp, 1] = (pA[kp, 1] + (s2 * pl0 - s0 * pl2)) + tau[j0 + 1]
            pA[kp, 2] = (pA[kp, 2] + (s0 * pl1 - s1 * pl0)) + tau[j0 + 2]
            pA[kp, 3] += pl0
            pA[kp, 4] += pl1
            pA[kp, 5] += pl2
        else:
            # U = I^A S, u = tau - S^T p^A
            for j in range(j0, j1):
                for r in range(6):
                    U[j, r] = (IA[k, r, 0] * S[j, 0] + IA[k, r, 1] * S[j, 1] + IA[k, r, 2] * S[j, 2]
                               + IA[k, r, 3] * S[j, 3] + IA[k, r, 4] * S[j, 4] + IA[k, r, 5] * S[j, 5])
                u[j] = tau[j] - (S[j, 0] * pA[k, 0] + S[j, 1] * pA[k, 1] + S[j, 2] * pA[k, 2]
                                 + S[j, 3] * pA[k, 3] + S[j, 4] * pA[k, 4] + S[j, 5] * pA[k, 5])
            extra = armature[k]
            if motor.shape[0] != 0 and motor[k, 3] != 0.0:  # a geared motor: U, u and D (eq 51b)
                extra += _motor_column(S, U, u, c, motor, k, j0)
            _joint_projection(S, U, Dinv[k], W, j0, nk, extra)
            if kp < 0:
                continue
            for r in range(6):
                for q in range(r, 6):
                    acc = IA[k, r, q]
                    for a in range(nk):
                        acc -= W[j0 + a, r] * U[j0 + a, q]
                    Ia[r, q] = acc
                    Ia[q, r] = acc
            for r in range(6):
                acc = pA[k, r] + (Ia[r, 0] * c[k, 0] + Ia[r, 1] * c[k, 1] + Ia[r, 2] * c[k, 2]
                                  + Ia[r, 3] * c[k, 3] + Ia[r, 4] * c[k, 4] + Ia[r, 5] * c[k, 5])
                for a in range(nk):
                    acc += W[j0 + a, r] * u[j0 + a]
                pa[r] = acc
            ratio = (Ia[3, 3] + Ia[4, 4] + Ia[5, 5]) / (3.0 * IA[kp, 3, 3]) if IA[kp, 3, 3] > 0.0 else 0.0
            if ratio > worst:
                worst = ratio
            _shift_inertia(Ia, s_w[ko], IA[kp], Dx, T, G)
            # forces to O^{k-1} = O^k - s^{k-1}: (n + s x f, f)
            s0, s1, s2 = s_w[ko, 0], s_w[ko, 1], s_w[ko, 2]
            pA[kp, 0] = (pA[kp, 0] + (s1 * pa[5] - s2 * pa[4])) + pa[0]
            pA[kp, 1] = (pA[kp, 1] + (s2 * pa[3] - s0 * pa[5])) + pa[1]
            pA[kp, 2] = (pA[kp, 2] + (s0 * pa[4] - s1 * pa[3])) + pa[2]
            pA[kp, 3] += pa[3]
            pA[kp, 4] += pa[4]
            pA[kp, 5] += pa[5]
    # forward: a = A^{k-1} + c^k, u'_k = D^-1 (u - U^T a), A^k = a + S u'_k (a tree's A^{parent}
    # is kept in pA[parent], which the forward sweep no longer reads)
    A0, A1, A2, A3, A4, A5 = a_base[0], a_base[1], a_base[2], a_base[3], a_base[4], a_base[5]
    for k in range(n):
        j0, j1 = col_start[k], col_start[k + 1]
        nk = j1 - j0
        if tree:
            kp = parent[k]
            if kp >= 0:
                A0, A1, A2, A3, A4, A5 = pA[kp, 0], pA[kp, 1], pA[kp, 2], pA[kp, 3], pA[kp, 4], pA[kp, 5]
                s0, s1, s2 = s_w[k, 0], s_w[k, 1], s_w[k, 2]
                A3 += A1 * s2 - A2 * s1
                A4 += A2 * s0 - A0 * s2
                A5 += A0 * s1 - A1 * s0
            else:
                A0, A1, A2, A3, A4, A5 = a_base[0], a_base[1], a_base[2], a_base[3], a_base[4], a_base[5]
        elif k > 0:
            # motions from O^{k-1} to O^k: (alpha, a + alpha x s^{k-1})
            s0, s1, s2 = s_w[k - 1, 0], s_w[k - 1, 1], s_w[k - 1, 2]
            A3 += A1 * s2 - A2 * s1
            A4 += A2 * s0 - A0 * s2
            A5 += A0 * s1 - A1 * s0
        A0 += c[k, 0]
        A1 += c[k, 1]
        A2 += c[k, 2]
        A3 += c[k, 3]
        A4 += c[k, 4]
        A5 += c[k, 5]
        if nk == SPHERICAL_DOF and not is_hinge[k]:
            # U^T a = J alpha + H a_lin
            x0 = u[j0] - (IA[k, 0, 0] * A0 + IA[k, 0, 1] * A1 + IA[k, 0, 2] * A2
                          + IA[k, 0, 3] * A3 + IA[k, 0, 4] * A4 + IA[k, 0, 5] * A5)
            x1 = u[j0 + 1] - (IA[k, 1, 0] * A0 + IA[k, 1, 1] * A1 + IA[k, 1, 2] * A2
                              + IA[k, 1, 3] * A3 + IA[k, 1, 4] * A4 + IA[k, 1, 5] * A5)
            x2 = u[j0 + 2] - (IA[k, 2, 0] * A0 + IA[k, 2, 1] * A1 + IA[k, 2, 2] * A2
                              + IA[k, 2, 3] * A3 + IA[k, 2, 4] * A4 + IA[k, 2, 5] * A5)
            ud0 = Dinv[k, 0, 0] * x0 + Dinv[k, 0, 1] * x1 + Dinv[k, 0, 2] * x2
            ud1 = Dinv[k, 1, 0] * x0 + Dinv[k, 1, 1] * x1 + Dinv[k, 1, 2] * x2
            ud2 = Dinv[k, 2, 0] * x0 + Dinv[k, 2, 1] * x1 + Dinv[k, 2, 2] * x2
            udot[j0], udot[j0 + 1], udot[j0 + 2] = ud0, ud1, ud2
            A0 += ud0
            A1 += ud1
            A2 += ud2
        else:
            for a in range(nk):
                j = j0 + a
                x[a] = u[j] - (U[j, 0] * A0 + U[j, 1] * A1 + U[j, 2] * A2
                               + U[j, 3] * A3 + U[j, 4] * A4 + U[j, 5] * A5)
            for a in range(nk):
                acc = 0.0
                for b in range(nk):
                    acc += Dinv[k, a, b] * x[b]
                udot[j0 + a] = acc
            for a in range(nk):
                j = j0 + a
                ud = udot[j]
                A0 += S[j, 0] * ud
                A1 += S[j, 1] * ud
                A2 += S[j, 2] * ud
                A3 += S[j, 3] * ud
                A4 += S[j, 4] * ud
                A5 += S[j, 5] * ud
        if tree:
            pA[k, 0], pA[k, 1], pA[k, 2], pA[k, 3], pA[k, 4], pA[k, 5] = A0, A1, A2, A3, A4, A5
    return worst


@_njit_inline
def _aba(is_hinge, col_start, e, tau, udot, heavy, parent):
    """Articulated-body algorithm: u' (N,) of the closure rows S_j . F_subtree(k(j)) = tau_j
    (eqs 44, 51, 54; Featherstone 2008, Table 7.1), about each body's O^k in world axes; e the
    Elimination's arrays.

    IA (n, 6, 6) and pA (n, 6) enter as the bodies' own inertias and bias forces (both are
    overwritten); c (n, 6): joint bias accelerations; a_base (6,): acceleration of the base at
    O^1; tau (N,): generalized forces of the columns. U, W (N, 6), u (N,), Dinv (n, 6, 6),
    Ia (6, 6), pa (6,), Dx, T, G (3, 3), x (6,): scratch. The elimination is `_aba_classic`
    unless it passes on to some body more than STABLE_ABA_RATIO times that body's own mass
    (checked only where a subtree is that much heavier than its carrier), then `_aba_stable`
    from the bodies' own inertias again (square-root factors and one step of iterative
    refinement; exact to ~1e-14 relative at mass ratios up to 1e7, about 2.5 x the cost).
    heavy: flags[FLAG_HEAVY], where that path (`_aba_heavy`) is compiled: it is called through
    this address, not compiled into every kernel that inlines this one (its allocations and
    square-root form are two thirds of the kernel's compile time, and no model below
    STABLE_ABA_RATIO ever runs it).
    """
    IA = e.IA
    n = IA.shape[0]
    after = 0.0
    worst = 0.0
    if parent.shape[0] != 0:  # a tree: each subtree's mass (summed in Dinv[k, 0, 0], free until
        # the elimination) against its parent's
        Dinv = e.Dinv
        for k in range(n):
            Dinv[k, 0, 0] = IA[k, 3, 3]
        for k in range(n - 1, -1, -1):
            kp = parent[k]
            if kp >= 0:
                Dinv[kp, 0, 0] += Dinv[k, 0, 0]
                if IA[kp, 3, 3] > 0.0 and Dinv[k, 0, 0] > worst * IA[kp, 3, 3]:
                    worst = Dinv[k, 0, 0] / IA[kp, 3, 3]
    else:
        for k in range(n - 1, 0, -1):
            after += IA[k, 3, 3]  # the mass of bodies k..n
            # a massless carrier has no inertia of its own for the elimination to lose
            if IA[k - 1, 3, 3] > 0.0 and after > worst * IA[k - 1, 3, 3]:
                worst = after / IA[k - 1, 3, 3]
    if worst <= STABLE_ABA_RATIO:  # no subtree can pass on more mass than it has
        _aba_classic(is_hinge, col_start, e, tau, udot, parent)
        return
    # a heavy subtree: what decides is the mass its elimination passes on (an articulated, not a
    # rigid, inertia: a uniform chain of 1000 links passes on about a link's mass at each joint),
    # known only once the classic elimination has run
    _heavy(heavy, is_hinge, col_start, e, tau, udot, parent)


@_njit_alloc
def _aba_heavy(is_hinge, col_start, e, tau, udot, parent):
    """`_aba` where a subtree is more than STABLE_ABA_RATIO times heavier than its carrier:
    `_aba_classic`, and `_aba_stable` from the bodies' own inertias again if the classic
    elimination passed on too much (arguments as `_aba`)."""
    IA, pA = e.IA, e.pA
    IA0 = IA.copy()
    pA0 = pA.copy()
    if _aba_classic(is_hinge, col_start, e, tau, udot, parent) > STABLE_ABA_RATIO:
        IA[:] = IA0
        pA[:] = pA0
        _aba_stable(is_hinge, col_start, e, tau, udot, parent)


@_njit_alloc
def _aba_stable(is_hinge, col_start, e, tau, udot, parent):
    """`_aba` for heavy subtrees on light carriers (and any other chain, at ~2.5 x the cost of
    `_aba_classic`).

    IA (n, 6, 6) and pA (n, 6) enter as the bodies' own inertias and bias forces; pA leaves
    as the articulated bias forces (IA is not updated past the bodies' own). c (n, 6): joint
    bias accelerations; a_base (6,): acceleration of the base at O^1; tau (N,): generalized
    forces of the columns. U (N, 6), u (N,): scratch; W (N, 6) leaves as U D^-1 and
    Dinv (n, 6, 6) as D^-1 of each joint.

    The articulated inertias are carried as square-root factors F (IA = F^T F), never formed:
    the projection I^a = I^A - U D^-1 U^T of a subtree far heavier (or lighter) than its
    carrier subtracts numbers of the heavy body's size to leave the light one's (the elbow
    mode of a heavy tip on light links), which loses digits as the mass ratio squared. Here
    the body's own factor (Cholesky of its inertia) is stacked on its child's and reduced by a
    Householder QR in joint-adapted axes Q = [S | N] (spherical: the identity; hinge: a
    reflector taking e^k to the first axis; slide: the same on the linear components, put
    first): R = [[R11, R12], [0, R22]], and then

        D = R11^T R11,  U D^-1 = Q [1; (R11^-1 R12)^T],  I^a = N R22^T R22 N^T

    so the factor passed to the parent is R22 N^T: no subtraction at all. Then one step of
    iterative refinement with the residual of the inverse dynamics (`_aba_resolve`) takes the
    last ~eps x ratio off (test/dynamics/test_heavy_tip.py). The base body's joint with a free base
    (six columns) is solved with its
    articulated inertia formed, F^T F (nothing passes on from it).
    """
    S, IA, pA, c, a_base, s_w, U, W, u, Dinv = e.S, e.IA, e.pA, e.c, e.a_base, e.s_w, e.U, e.W, e.u, e.Dinv
    armature, motor = e.armature, e.motor
    motors = motor.shape[0] != 0
    n = IA.shape[0]
    tree = parent.shape[0] != 0
    # a tree: each body's children's factors, reduced to at most six rows as they arrive (a QR
    # of the stacked rows keeps F^T F), and how many rows each holds
    pending = np.zeros((n if tree else 0, 6, 6))
    npending = np.zeros(n if tree else 0, dtype=np.int64)
    merged = np.zeros((12, 6))
    vm = np.empty(12)
    # a tree's locked rotors of each body's children's motors, m m^T / (J G^2) summed (as below)
    locked = np.zeros((n if tree and motors else 0, 3, 3))
    has_locked = np.zeros(n if tree and motors else 0, dtype=np.bool_)
    for j in range(locked.shape[0]):
        kp = parent[j]
        if kp >= 0 and motor[j, 3] != 0.0:
            has_locked[kp] = True
            for r in range(3):
                for b in range(3):
                    locked[kp, r, b] += motor[j, r] * motor[j, b] / motor[j, 3]
    Ia = np.empty((6, 6))
    pa = np.empty(6)
    K = np.empty((6, 6))
    St = np.zeros((12, 6))  # stacked factors: own (6 rows), child (up to 6 rows)
    Fc = np.zeros((6, 6))  # the child's factor, moved to this body's O^k
    v = np.empty(12)
    H = np.empty((3, 3))
    Ri = np.empty((3, 3))  # R11^-1
    G = np.empty((3, 5))  # R11^-1 R12
    z = np.empty(6)
    nc = 0
    pb = pA.copy()  # the bodies' own bias forces, for the residual
    acc_body = np.empty((n, 6))  # A^k, for the residual
    # backward: I^a = I^A - U D^-1 U^T, p^a = p^A + I^a c + U D^-1 u, to the parent's O^{k-1}
    for k in range(n - 1, -1, -1):
        j0, j1 = col_start[k], col_start[k + 1]
        nk = j1 - j0
        IAk, pAk, D = IA[k], pA[k], Dinv[k]
        kp, ko = (parent[k], k) if tree else (k - 1, k - 1)
        if tree:  # the children's factors, moved to O^k already
            nc = npending[k]
            for b in range(nc):
                for r in range(6):
                    Fc[b, r] = pending[k, b, r]
        for j in range(j0, j1):
            u[j] = tau[j] - dot6(S[j], pAk)
        if motors and motor[k, 3] != 0.0:  # u' = u + m . c^k (eq 51b, as `_motor_column`)
            u[j0] += motor[k, 0] * c[k, 0] + motor[k, 1] * c[k, 1] + motor[k, 2] * c[k, 2]
        child_motor = motors and tree and has_locked[k]
        if child_motor:  # the locked rotors of the children's motors, as below
            for r in range(6):
                for b in range(6):
                    Ia[r, b] = IAk[r, b] - (locked[k, r, b] if r < 3 and b < 3 else 0.0)
            _chol_upper6(Ia, K)
        elif tree:
            _chol_upper6(IAk, K)
        elif motors and k + 1 < n and motor[k + 1, 3] != 0.0:
            # the locked rotor J a a^T = m m^T / (J G^2) of the child's motor is factored with the
            # child (its I^a below is then positive semidefinite): the own factor without it
            for r in range(6):
                for q in range(6):
                    Ia[r, q] = IAk[r, q]
            for r in range(3):
                for q in range(3):
                    Ia[r, q] -= motor[k + 1, r] * motor[k + 1, q] / motor[k + 1, 3]
            _chol_upper6(Ia, K)
        else:
            _chol_upper6(IAk, K)
        if nk != 1 and nk != SPHERICAL_DOF:
            # free base and first joint (k = 0): I^A = F^T F formed, D = S^T I^A S
            for r in range(6):
                for q in range(r, 6):
                    acc = 0.0
                    for i in range(r + 1):
                        acc += K[i, r] * K[i, q]
                    for i in range(nc):
                        acc += Fc[i, r] * Fc[i, q]
                    Ia[r, q] = acc
                    Ia[q, r] = acc
            for j in range(j0, j1):
                for r in range(6):
                    U[j, r] = dot6(Ia[r], S[j])
            _joint_projection(S, U, D, W, j0, nk, 0.0)
            continue
        # the stacked factor [F_own; F_child] in joint axes Q: a hinge's angular columns (ro = 0)
        # times H, then its linear ones (oo = 3); a slide's (S = (0, e)) linear columns (ro = 3)
        # times H first, then its angular ones (oo = 0): the joint's own axis is column 0
        sigma = 1.0
        hinge = is_hinge[k]
        ro, oo = 0, 3
        if hinge:
            if S[j0, 0] == 0.0 and S[j0, 1] == 0.0 and S[j0, 2] == 0.0:
                ro, oo = 3, 0
            sigma = _hinge_reflector(S[j0, ro:ro + 3], H)
        for i in range(6 + nc):
            for q in range(6):
                St[i, q] = K[i, q] if i < 6 else Fc[i - 6, q]
            if hinge:
                x0, x1, x2 = St[i, ro], St[i, ro + 1], St[i, ro + 2]
                z0, z1, z2 = St[i, oo], St[i, oo + 1], St[i, oo + 2]
                for a in range(3):
                    St[i, a] = x0 * H[0, a] + x1 * H[1, a] + x2 * H[2, a]
                if ro == 3:
                    St[i, 3], St[i, 4], St[i, 5] = z0, z1, z2
        _householder_qr6(St, 6 + nc, v)
        # D^-1 = R11^-1 R11^-T; G = R11^-1 R12
        for a in range(nk - 1, -1, -1):
            for b in range(nk):
                acc = (1.0 if a == b else 0.0)
                for i in range(a + 1, nk):
                    acc -= St[a, i] * Ri[i, b]
                Ri[a, b] = acc / St[a, a]
        for a in range(nk):
            for b in range(a, nk):
                acc = 0.0
                for i in range(max(a, b), nk):
                    acc += Ri[a, i] * Ri[b, i]
                D[a, b] = acc
                D[b, a] = acc
        m2 = 6 - nk
        for a in range(nk):
            for b in range(m2):
                acc = 0.0
                for i in range(a, nk):
                    acc += Ri[a, i] * St[i, nk + b]
                G[a, b] = acc
        # W = U D^-1 = sigma Q [1; G^T]: column a of the joint, Q e_a = sigma S_a, Q e_{nk+b}
        for a in range(nk):
            j = j0 + a
            for r in range(6):
                W[j, r] = S[j, r]
            for b in range(m2):
                g = sigma * G[a, b]
                if hinge:
                    if b < 2:
                        for r in range(3):
                            W[j, ro + r] += g * H[r, 1 + b]
                    else:
                        W[j, oo + b - 2] += g
                else:
                    W[j, 3 + b] += g
        # a hinge's armature a: D = D0 + a (D0 = R11^2, the body's own), W = U / D is the W
        # above (U / D0) times D0 / D, and I^a = I^A - U U^T / D gains the row sqrt(a D0 / D) W
        # (U / D0) on top of R22 N^T: I^a = N R22^T R22 N^T + (a / (D0 D)) U U^T
        rows = m2
        if hinge and armature[k] != 0.0:
            D0 = St[0, 0] * St[0, 0]
            Dk = D0 + armature[k]
            D[0, 0] = 1.0 / Dk
            scale = math.sqrt(armature[k] * D0 / Dk)
            for r in range(6):
                Ia[m2, r] = scale * W[j0, r]
                W[j0, r] *= D0 / Dk
            rows = m2 + 1
        elif hinge and motors and motor[k, 3] != 0.0:
            # a geared motor (m = J G a, d = J G^2): D = D0 + d, W = (U + (m, 0)) / D with U = D0 W,
            # and the articulated inertia with the locked rotor, I^A + J a a^T - W D W^T, is
            # N R22^T R22 N^T + v v^T / D, v = sqrt(d D0) W - sqrt(D0 / d) (m, 0): one more row
            D0 = St[0, 0] * St[0, 0]
            d = motor[k, 3]
            Dk = D0 + d
            D[0, 0] = 1.0 / Dk
            scale = math.sqrt(D0 / Dk)
            sd = math.sqrt(d)
            for r in range(6):
                mr = motor[k, r] if r < 3 else 0.0
                Ia[m2, r] = scale * (sd * W[j0, r] - mr / sd)
                W[j0, r] = (D0 * W[j0, r] + mr) / Dk
            rows = m2 + 1
        if kp < 0:
            continue
        # the factor passed on: R22 N^T, N = Q[:, nk:] ((6 - nk) rows, in world axes)
        for b in range(m2):
            for r in range(6):
                Ia[b, r] = 0.0
            for i in range(b, m2):
                f = St[nk + b, nk + i]
                if hinge:
                    if i < 2:
                        for r in range(3):
                            Ia[b, ro + r] += f * H[r, 1 + i]
                    else:
                        Ia[b, oo + i - 2] += f
                else:
                    Ia[b, 3 + i] += f
        # p^a = p^A + I^a c + U D^-1 u, I^a c = F^T (F c)
        for r in range(6):
            acc = pAk[r]
            for a in range(nk):
                acc += W[j0 + a, r] * u[j0 + a]
            pa[r] = acc
        for b in range(rows):
            z[b] = dot6(Ia[b], c[k])
        for b in range(rows):
            for r in range(6):
                pa[r] += Ia[b, r] * z[b]
        if hinge and motors and motor[k, 3] != 0.0:  # I^a c without the locked rotor (the parent's)
            f = (motor[k, 0] * c[k, 0] + motor[k, 1] * c[k, 1] + motor[k, 2] * c[k, 2]) / motor[k, 3]
            for r in range(3):
                pa[r] -= motor[k, r] * f
        # the factor moved to O^{k-1} = O^k - s^{k-1}: rows (f_ang, f_lin) X = (f_ang + s x f_lin, f_lin)
        d = s_w[ko]
        nc = rows
        for b in range(rows):
            fl0, fl1, fl2 = Ia[b, 3], Ia[b, 4], Ia[b, 5]
            Fc[b, 0] = Ia[b, 0] + (d[1] * fl2 - d[2] * fl1)
            Fc[b, 1] = Ia[b, 1] + (d[2] * fl0 - d[0] * fl2)
            Fc[b, 2] = Ia[b, 2] + (d[0] * fl1 - d[1] * fl0)
            Fc[b, 3], Fc[b, 4], Fc[b, 5] = fl0, fl1, fl2
        if tree:  # joins the parent's other children's: [pending; Fc] reduced by a QR
            m0 = npending[kp]
            for b in range(m0):
                for r in range(6):
                    merged[b, r] = pending[kp, b, r]
            for b in range(rows):
                for r in range(6):
                    merged[m0 + b, r] = Fc[b, r]
            mr = m0 + rows
            if m0 > 0:
                _householder_qr6(merged, mr, vm)
                mr = min(mr, 6)
            for b in range(mr):
                for r in range(6):
                    pending[kp, b, r] = merged[b, r]
            npending[kp] = mr
        # forces to O^{k-1} = O^k - s^{k-1}: (n + s x f, f)
        vec_cross_add(s_w[ko], pa[3:], pA[kp, :3])
        for r in range(6):
            pA[kp, r] += pa[r]
    # forward: a = A^{k-1} + c^k, u'_k = D^-1 u - (U D^-1)^T a, A^k = a + S u'_k
    A = np.empty(6)
    for r in range(6):
        A[r] = a_base[r]
    x = np.empty(MAX_JOINT_DOF)
    for k in range(n):
        j0, j1 = col_start[k], col_start[k + 1]
        nk = j1 - j0
        D = Dinv[k]
        if tree:  # from the parent's A (or the base's)
            kp = parent[k]
            for r in range(6):
                A[r] = acc_body[kp, r] if kp >= 0 else a_base[r]
            if kp >= 0:
                vec_cross_add(A[:3], s_w[k], A[3:])
        elif k > 0:
            # motions from O^{k-1} to O^k: (alpha, a + alpha x s^{k-1})
            vec_cross_add(A[:3], s_w[k - 1], A[3:])
        for r in range(6):
            A[r] += c[k, r]
        for a in range(nk):
            x[a] = dot6(W[j0 + a], A)
        for a in range(nk):
            acc = 0.0
            for b in range(nk):
                acc += D[a, b] * u[j0 + b]
            udot[j0 + a] = acc - x[a]
        for a in range(nk):
            for r in range(6):
                A[r] += S[j0 + a, r] * udot[j0 + a]
        for r in range(6):
            acc_body[k, r] = A[r]
    # one step of iterative refinement (Wilkinson): the residual of the closure rows by the
    # inverse dynamics (RNEA: forces of the accelerations just found, summed from the tip), then
    # u' += the same elimination applied to it (M du' = residual, no bias, no base motion)
    F = pb
    for k in range(n):
        for r in range(6):
            F[k, r] += dot6(IA[k, r], acc_body[k])
    if motors:  # the motors' J G phi'' a on their parents
        for k in range(1, n):
            kp = parent[k] if tree else k - 1
            if kp < 0:
                continue
            for r in range(3):
                F[kp, r] += motor[k, r] * udot[col_start[k]]
    res = np.empty(u.shape[0])
    for k in range(n - 1, -1, -1):
        kp, ko = (parent[k], k) if tree else (k - 1, k - 1)
        for j in range(col_start[k], col_start[k + 1]):
            res[j] = tau[j] - dot6(S[j], F[k])
            if armature[k] != 0.0 and col_start[k + 1] - col_start[k] == 1:
                res[j] -= armature[k] * udot[j]
            if motors and motor[k, 3] != 0.0:  # (51b)
                res[j] -= (motor[k, 0] * acc_body[kp, 0] + motor[k, 1] * acc_body[kp, 1]
                           + motor[k, 2] * acc_body[kp, 2] + motor[k, 3] * udot[j])
        if kp >= 0:
            vec_cross_add(s_w[ko], F[k, 3:], F[kp, :3])
            for r in range(6):
                F[kp, r] += F[k, r]
    _aba_resolve(col_start, S, s_w, W, Dinv, res, u, F, udot, parent)


@_njit_alloc
def _aba_resolve(col_start, S, s_w, W, Dinv, rhs, u, P, udot, parent):
    """udot += M^-1 rhs (N,) with the elimination `_aba` left in W (U D^-1) and Dinv: its two
    sweeps with no bias and no base motion. u (N,), P (n, 6): scratch; parent: a tree's, or (0,)."""
    n = P.shape[0]
    tree = parent.shape[0] != 0
    P[:, :] = 0.0
    pa = np.empty(6)
    for k in range(n - 1, -1, -1):
        j0, j1 = col_start[k], col_start[k + 1]
        kp, ko = (parent[k], k) if tree else (k - 1, k - 1)
        for j in range(j0, j1):
            u[j] = rhs[j] - dot6(S[j], P[k])
        if kp < 0:
            continue
        for r in range(6):
            acc = P[k, r]
            for j in range(j0, j1):
                acc += W[j, r] * u[j]
            pa[r] = acc
        vec_cross_add(s_w[ko], pa[3:], P[kp, :3])
        for r in range(6):
            P[kp, r] += pa[r]
    A = np.zeros(6)
    At = np.zeros((n if tree else 0, 6))  # a tree's body accelerations
    for k in range(n):
        j0, j1 = col_start[k], col_start[k + 1]
        nk = j1 - j0
        D = Dinv[k]
        if tree:
            kp = parent[k]
            for r in range(6):
                A[r] = At[kp, r] if kp >= 0 else 0.0
            if kp >= 0:
                vec_cross_add(A[:3], s_w[k], A[3:])
        elif k > 0:
            vec_cross_add(A[:3], s_w[k - 1], A[3:])
        for a in range(nk):
            acc = -dot6(W[j0 + a], A)
            for b in range(nk):
                acc += D[a, b] * u[j0 + b]
            udot[j0 + a] += acc
            for r in range(6):
                A[r] += S[j0 + a, r] * acc
        if tree:
            for r in range(6):
                At[k, r] = A[r]


# --- the heavy-subtree path, compiled apart and called through its address ---------------------
def heavy_subtrees(mass, parent=None) -> bool:
    """True when `_aba` takes its heavy-subtree path for bodies of these masses (n,): the same
    test in the same operations as `_aba`'s (the mass of bodies k.. against body k - 1's; on a
    tree, of k's subtree against its parent's, `parent` (n,) the tree's)."""
    after = 0.0
    worst = 0.0
    if parent is not None:
        sub = [float(m) for m in mass]
        for k in range(len(mass) - 1, -1, -1):
            kp = int(parent[k])
            if kp >= 0:
                sub[kp] += sub[k]
                if float(mass[kp]) > 0.0 and sub[k] > worst * float(mass[kp]):
                    worst = sub[k] / float(mass[kp])
        return not worst <= STABLE_ABA_RATIO
    for k in range(len(mass) - 1, 0, -1):
        after += float(mass[k])
        if float(mass[k - 1]) > 0.0 and after > worst * float(mass[k - 1]):
            worst = after / float(mass[k - 1])
    return not worst <= STABLE_ABA_RATIO


#: `_heavy_entry`'s arguments: the addresses of `_aba_heavy`'s 22 arrays, then the motors' rows
#: (n or 0), the parents' (n or 0), n and N
HEAVY_ENTRY_ARGUMENTS = 27


if jit.compiling():
    @_njit_inline
    def _heavy(address, is_hinge, col_start, e, tau, udot, parent):
        """`_aba_heavy` through the address of its compiled entry (`heavy_elimination_address`).
        Address 0 (a model built without it, `chain_model` says why that cannot happen with
        heavy subtrees): u' not a number, which the integrators report as a non-finite rhs."""
        if address == 0:
            for j in range(udot.shape[0]):
                udot[j] = np.nan
            return
        call_address(address, (
            address_of(is_hinge), address_of(col_start), address_of(e.S), address_of(e.IA), address_of(e.pA),
            address_of(e.c), address_of(tau), address_of(e.a_base), address_of(e.s_w), address_of(e.U),
            address_of(e.W), address_of(e.u), address_of(e.Dinv), address_of(udot), address_of(e.Ia),
            address_of(e.pa), address_of(e.Dx), address_of(e.T), address_of(e.G), address_of(e.x),
            address_of(e.armature), address_of(e.motor), address_of(parent), e.motor.shape[0],
            parent.shape[0], e.IA.shape[0], e.S.shape[0]))

    def _heavy_entry(is_hinge, col_start, S, IA, pA, c, tau, a_base, s_w, U, W, u, Dinv, udot, Ia, pa,
                     Dx, T, G, x, armature, motor, parent, n_motor, n_parent, n, N):
        """`_aba_heavy` on the arrays at these addresses (C-contiguous, the shapes `_aba` gives
        them for n bodies and N columns): compiled as a C function (`heavy_elimination_address`)."""
        f = np.float64
        e = Elimination(
            block2(vector_at(S, 6 * N, f), 0, N, 6), block3(vector_at(IA, 36 * n, f), 0, n, 6, 6),
            block2(vector_at(pA, 6 * n, f), 0, n, 6), block2(vector_at(c, 6 * n, f), 0, n, 6),
            vector_at(a_base, 6, f), block2(vector_at(s_w, 3 * n, f), 0, n, 3),
            block2(vector_at(U, 6 * N, f), 0, N, 6), block2(vector_at(W, 6 * N, f), 0, N, 6),
            vector_at(u, N, f), block3(vector_at(Dinv, 36 * n, f), 0, n, 6, 6),
            block2(vector_at(Ia, 36, f), 0, 6, 6), vector_at(pa, 6, f),
            block2(vector_at(Dx, 9, f), 0, 3, 3), block2(vector_at(T, 9, f), 0, 3, 3),
            block2(vector_at(G, 9, f), 0, 3, 3), vector_at(x, 6, f), vector_at(armature, n, f),
            block2(vector_at(motor, 4 * n_motor, f), 0, n_motor, 4))
        _aba_heavy(vector_at(is_hinge, n, np.bool_), vector_at(col_start, n + 1, np.int64), e,
                   vector_at(tau, N, f), vector_at(udot, N, f), vector_at(parent, n_parent, np.int64))

    @_njit_inline
    def records_at(descriptor):
        """The records a descriptor (`describe`) gives the addresses and sizes of: (ChainModel,
        Workspace, HeldInputs) of C-contiguous views, of the types every caller passes (so the
        kernel's one specialisation serves them), owned elsewhere."""
        f, i = np.float64, np.int64
        d = vector_at(descriptor, DESCRIPTOR_SIZE, i)
        n, N, nt = d[D_N], d[D_NCOL], d[D_NT]
        a = d[D_MODEL:D_WORK]
        flags = vector_at(a[13], FLAGS_SIZE, i)
        model = ChainModel(
            vector_at(a[0], n, np.bool_), vector_at(a[1], n, i), vector_at(a[2], n, i),
            vector_at(a[3], n + 1, i), block2(vector_at(a[4], 3 * n, f), 0, n, 3),
            block2(vector_at(a[5], 3 * n, f), 0, n, 3), vector_at(a[6], n, f),
            block2(vector_at(a[7], 3 * n, f), 0, n, 3), block3(vector_at(a[8], 9 * n, f), 0, n, 3, 3),
            block2(vector_at(a[9], 3 * n, f), 0, n, 3), vector_at(a[10], nt, i),
            block2(vector_at(a[11], 3 * nt, f), 0, nt, 3), vector_at(a[12], nt, f),
            flags, vector_at(a[14], 7, f), vector_at(a[15], n, f),
            block2(vector_at(a[16], 2 * n, f), 0, n, 2), block2(vector_at(a[17], 5 * n, f), 0, n, 5),
            block2(vector_at(a[18], 5 * n, f), 0, n, 5),
            vector_at(a[19], n, np.bool_), vector_at(a[20], n * (flags[FLAG_TREE] != 0), i))
        h = d[D_INPUTS:D_N]
        inputs = HeldInputs(vector_at(h[0], 1, f), vector_at(h[1], nt, f), vector_at(h[2], nt, f),
                            vector_at(h[3], nt, f), vector_at(h[4], N, f))
        return model, Workspace(vector_at(d[D_WORK], d[D_NWORK], f), d), inputs

    def _kernel_entry(t, y, ydot, size, descriptor):
        """`rhs_kernel` on y, ydot (`size` floats at these addresses) and the records `descriptor`
        (an address) describes: compiled as a C function (`kernel_address`)."""
        model, data, inputs = records_at(descriptor)
        _rhs(t, vector_at(y, size, np.float64), vector_at(ydot, size, np.float64), model, data, inputs)

    @_njit_inline
    def rhs_call(t, y, ydot, model, data, inputs):
        """`rhs_kernel` (same arguments, y and ydot C-contiguous; `data` the workspace that
        describes `model` and `inputs`) through its compiled C function at flags[FLAG_KERNEL]:
        for compiled loops, which then do not compile the kernel in."""
        call_address(model.flags[FLAG_KERNEL],
                     (t, address_of(y), address_of(ydot), y.shape[0], address_of(data.descriptor)))

    def _null_entry(t, y, ydot, size, descriptor):
        """`_kernel_entry`'s signature, y' = 0: compiled as a C function (`null_kernel_address`)."""
        v = vector_at(ydot, size, np.float64)
        for k in range(size):
            v[k] = 0.0
else:  # plain Python: the heavy path and the kernel called directly
    def _heavy(address, is_hinge, col_start, e, tau, udot, parent):
        _aba_heavy(is_hinge, col_start, e, tau, udot, parent)

    def rhs_call(*arguments):
        rhs_kernel(*arguments)


def kernel_signature(*extra):
    """The numba signature of the kernel's C function (`_kernel_entry`: t, the addresses of y and
    ydot, their size, the descriptor's address), `extra` argument types after it (fast_canonical's
    field adds four)."""
    f, i = numba.types.float64, numba.types.int64
    return numba.types.void(f, i, i, i, i, *extra)


def heavy_elimination_address() -> int:
    """The address of `_aba_heavy` compiled as a C function of HEAVY_ENTRY_ARGUMENTS int64s
    (`_heavy_entry`), compiled or loaded from numba's disk cache on the first call (12-19 s of
    CPU compiled, measured: less when the kernel's stages are compiled already); 0 without numba or with
    NUMBA_DISABLE_JIT,
    where `_aba` calls it directly."""
    if not jit.compiling():
        return 0
    return jit.c_address(_heavy_entry, lambda: numba.types.void(*(numba.types.int64,) * HEAVY_ENTRY_ARGUMENTS),
                         DEPENDENCIES, _nrt=True)


def kernel_address() -> int:
    """The address of `rhs_kernel` compiled as a C function (`_kernel_entry`: t, the arrays'
    addresses, t0, their sizes), compiled or loaded from numba's disk cache on the first call;
    0 without numba or with NUMBA_DISABLE_JIT, where `rhs_call` calls the kernel directly."""
    if not jit.compiling():
        return 0
    return jit.c_address(_kernel_entry, kernel_signature, DEPENDENCIES, _nrt=False)


def null_kernel_address() -> int:
    """The address of a C function of `kernel_address`'s signature that only sets y' = 0: for
    compiling the loops and outputs without the dynamics (their code does not depend on the
    kernel they call through flags[FLAG_KERNEL]: gyro_sim.warmup's helper builds its systems on
    it). Never for results. 0 without numba or with NUMBA_DISABLE_JIT."""
    if not jit.compiling():
        return 0
    return jit.c_address(_null_entry, kernel_signature, DEPENDENCIES, _nrt=False)


@_njit_inline
def workspace_views(work, n, N, nt):
    """`rhs_kernel`'s workspace (`workspace`) cut into its views, the one place its layout is
    written: R, s_w, hk, Aw, e_w, w, vO, c (the kinematics, left there by every call), I6, pb,
    Dinv, lam_b, dlam_b, S, U, W, u, p, then the fixed scratch Ia, pa, Dx, T, G, x, a_base."""
    o = 0
    R = block3(work, o, n, 3, 3)
    o += 9 * n
    s_w = block2(work, o, n, 3)
    o += 3 * n
    hk = block2(work, o, n, 3)
    o += 3 * n
    Aw = block3(work, o, n, 3, 3)
    o += 9 * n
    e_w = block2(work, o, n, 3)
    o += 3 * n
    w = block2(work, o, n, 3)
    o += 3 * n
    vO = block2(work, o, n, 3)
    o += 3 * n
    c = block2(work, o, n, 6)
    o += 6 * n
    I6 = block3(work, o, n, 6, 6)
    o += 36 * n
    pb = block2(work, o, n, 6)
    o += 6 * n
    Dinv = block3(work, o, n, 6, 6)
    o += 36 * n
    lam_b = block2(work, o, n, 3)
    o += 3 * n
    dlam_b = block2(work, o, n, 3)
    o += 3 * n
    S = block2(work, o, N, 6)
    o += 6 * N
    U = block2(work, o, N, 6)
    o += 6 * N
    W = block2(work, o, N, 6)
    o += 6 * N
    u = block1(work, o, N)
    o += N
    p = block1(work, o, nt)
    o += nt
    # fixed scratch (WORK_FIXED): Ia 36, pa 6, Dx 9, T 9, G 9, x 6, a_base 6
    Ia = block2(work, o, 6, 6)
    pa = block1(work, o + 36, 6)
    Dx = block2(work, o + 42, 3, 3)
    T = block2(work, o + 51, 3, 3)
    G = block2(work, o + 60, 3, 3)
    x = block1(work, o + 69, 6)
    a_base = block1(work, o + 75, 6)
    return (R, s_w, hk, Aw, e_w, w, vO, c, I6, pb, Dinv, lam_b, dlam_b, S, U, W, u, p,
            Ia, pa, Dx, T, G, x, a_base)


@_njit
def rhs_kernel(t, y, ydot, model, data, inputs):
    """y' (size,) at (t, y) into ydot: `_rhs` compiled on its own, for callers from Python with
    records of numpy arrays."""
    _rhs(t, y, ydot, model, data, inputs)


@_njit_inline
def _rhs(t, y, ydot, model, data, inputs):
    """y' (size,) at (t, y) into ydot: what system.ChainODE.rhs computes, for the ChainModel
    `model` (`chain_model`), the Workspace `data` (its scratch: n WORK_PER_BODY + N
    WORK_PER_COLUMN + nt + WORK_FIXED floats; nothing is allocated per call) and the
    HeldInputs `inputs`.

    model.flags (int, FLAGS_SIZE): base type, has gravity, has lambda (rotors), i_r0, i_vel,
    i_kappa, N, the heavy path's address (FLAG_HEAVY), this kernel's C function's (FLAG_KERNEL:
    for the compiled loops, `rhs_call`). model.base (float, 7): moving-base amplitude (3),
    W = 2 pi f, gravity (3).
    Held inputs: torque-rotor spins p_i = p0_i + pdot_i (t - t0) (eq 29), their torques
    L_rotor, the generalized forces tau (N,) of the columns (hinge commands, eq 51).
    A stateful model (flags[FLAG_ACTUATORS]) reads the spins from y instead and applies the
    commands through its actuators' speed cut and friction (`actuate`).
    """
    (is_hinge, qrow, own_col, col_start, hinge_axis, s, mass, first_moment, inertia, lam_speed, torque_body,
     torque_axis, torque_A, flags, base, armature, spring, servo, motor, is_slide, parent) = model
    work = data.work
    t0, p0, pdot, L_rotor, tau = inputs.t0[0], inputs.p0, inputs.pdot, inputs.L_rotor, inputs.tau
    base_type = flags[0]
    i_r0, i_vel, i_kap, N = flags[3], flags[4], flags[5], flags[6]
    base_amplitude, base_omega = base[0:3], base[3]
    n = mass.shape[0]
    nt = torque_body.shape[0]
    (R, s_w, hk, Aw, e_w, w, vO, c, I6, pb, Dinv, lam_b, dlam_b, S, U, W, u, p,
     Ia, pa, Dx, T, G, x, a_base) = workspace_views(work, n, N, nt)

    # positions, velocities
    body_positions(y, model, R, s_w, hk, Aw, e_w)
    body_velocities(t, y, model, s_w, e_w, w, vO, c)
    L_applied, tau_applied = L_rotor, tau
    if flags[FLAG_ACTUATORS] != 0:  # spins and works are states; the torques applied at this state
        L_applied, tau_applied = actuate(y, ydot, model, data, inputs, R, w, p)
    else:  # bias forces: p_i(t) = p_i(t0) + (L_i / A_i)(t - t0) (eq 29)
        for i in range(nt):
            p[i] = p0[i] + pdot[i] * (t - t0)
    if flags[FLAG_SPRINGS] != 0:  # the springs' moments -k (phi - phi_ref) join the hinges'
        with_springs = block1(work, work.shape[0] - N, N)
        _spring_moments(y, model, tau_applied, with_springs)
        tau_applied = with_springs
    bias_forces(model, R, hk, Aw, w, vO, p, L_applied, lam_b, dlam_b, I6, pb)
    motor_w = block2(work, 0, 0, 4)
    if flags[FLAG_MOTORS] != 0:  # the motors' m = J G a (world) and their gyroscopic moments
        motor_w = block2(work, motor_offset(work, flags, n), n, 4)
        motor_axes(model, R, motor_w)
        motor_gyroscopic(y, model, w, motor_w, pb)
    # ABA
    _joint_columns(is_hinge, is_slide, own_col, base_type, e_w, S)
    for a in range(6):
        a_base[a] = 0.0
    if base_type == BASE_MOVING:
        sw = -base_omega * base_omega * math.sin(base_omega * t)
        for a in range(3):
            a_base[3 + a] = base_amplitude[a] * sw
    _aba(is_hinge, col_start,
         Elimination(S, I6, pb, c, a_base, s_w, U, W, u, Dinv, Ia, pa, Dx, T, G, x, armature, motor_w),
         tau_applied, ydot[i_vel:i_vel + N], flags[FLAG_HEAVY], parent)
    # y'
    if base_type == BASE_FREE:
        for a in range(3):
            ydot[i_r0 + a] = y[i_vel + a]
    for k in range(n):
        i = qrow[k]
        if is_hinge[k]:
            ydot[i] = y[i_vel + own_col[k]]  # phi_k'
        else:
            ydot[i], ydot[i + 1], ydot[i + 2], ydot[i + 3] = _quat_rate(
                y[i], y[i + 1], y[i + 2], y[i + 3], w[k, 0], w[k, 1], w[k, 2])
    for i in range(nt):
        k = torque_body[i]
        ax0, ax1, ax2 = torque_axis[i, 0], torque_axis[i, 1], torque_axis[i, 2]
        e0 = R[k, 0, 0] * ax0 + R[k, 0, 1] * ax1 + R[k, 0, 2] * ax2
        e1 = R[k, 1, 0] * ax0 + R[k, 1, 1] * ax1 + R[k, 1, 2] * ax2
        e2 = R[k, 2, 0] * ax0 + R[k, 2, 1] * ax1 + R[k, 2, 2] * ax2
        ydot[i_kap + i] = _rotor_angle_rate(p[i], w[k, 0], w[k, 1], w[k, 2], e0, e1, e2)


@_njit_inline
def actuate(y, ydot, model, data, inputs, R, w, p):
    """A stateful model's applied torques (gyro_sim.dynamics.reference.applied_torques): the
    spins p from y, the rotor torques (nt,) and generalized forces (N,) applied (views of the
    workspace's tail), and y' of the spins (eq 29) and of the works (the motors' power,
    friction's)."""
    is_hinge, own_col, torque_body, torque_axis, torque_A, flags = (model.is_hinge, model.own_col, model.torque_body,
                                                                    model.torque_axis, model.torque_A, model.flags)
    work, L_rotor, tau = data.work, inputs.L_rotor, inputs.tau
    n, N, nt, i_vel = model.mass.shape[0], flags[6], torque_body.shape[0], flags[4]
    i_spin, i_work = flags[FLAG_I_SPIN], flags[FLAG_I_WORK]
    rotor_at = n * WORK_PER_BODY + N * WORK_PER_COLUMN + nt * WORK_PER_ROTOR + WORK_FIXED
    hinge_at = rotor_at + nt * ACTUATOR_PARAMETERS
    L_at = hinge_at + n * ACTUATOR_PARAMETERS
    L_applied = block1(work, L_at, nt)
    tau_applied = block1(work, L_at + nt, N)
    motor_power = 0.0
    friction_power = 0.0
    for i in range(nt):
        p[i] = y[i_spin + i]
        k = torque_body[i]
        ax0, ax1, ax2 = torque_axis[i, 0], torque_axis[i, 1], torque_axis[i, 2]
        e0 = R[k, 0, 0] * ax0 + R[k, 0, 1] * ax1 + R[k, 0, 2] * ax2
        e1 = R[k, 1, 0] * ax0 + R[k, 1, 1] * ax1 + R[k, 1, 2] * ax2
        e2 = R[k, 2, 0] * ax0 + R[k, 2, 1] * ax1 + R[k, 2, 2] * ax2
        rate = _rotor_angle_rate(p[i], w[k, 0], w[k, 1], w[k, 2], e0, e1, e2)
        o = rotor_at + i * ACTUATOR_PARAMETERS
        motor = _speed_cut(L_rotor[i], rate, work[o])
        friction = _friction_torque(rate, work, o)
        L_applied[i] = motor + friction
        ydot[i_spin + i] = (motor + friction) / torque_A[i]
        motor_power += motor * rate
        friction_power += friction * rate
    motor = tau
    if flags[FLAG_SERVOS] != 0:  # the servos' moments at this state from their held drives
        motor = block1(work, servo_offset(work, flags), N)
        servo_moments(y, model, tau, motor)
    for j in range(N):
        tau_applied[j] = motor[j]
    for k in range(n):
        if is_hinge[k]:
            col = own_col[k]
            rate = y[i_vel + col]
            friction = _friction_torque(rate, work, hinge_at + k * ACTUATOR_PARAMETERS)
            tau_applied[col] += friction
            motor_power += motor[col] * rate
            friction_power += friction * rate
    ydot[i_work] = motor_power
    ydot[i_work + 1] = friction_power
    return L_applied, tau_applied


@_njit_inline
def servo_moments(y, model, tau, out):
    """out (N,): the generalized forces tau with each servo's hinge's held drive d turned into
    its moment gear clip(d + b1 gear phi + b2 gear phi', force range) at y
    (gyro_sim.dynamics.reference.servo_moments); out is `servo_offset`'s block of the workspace."""
    N, i_vel = model.flags[6], model.flags[4]
    for j in range(N):
        out[j] = tau[j]
    for k in range(model.mass.shape[0]):
        gear = model.servo[k, 0]
        if model.is_hinge[k] and gear != 0.0:
            col = model.own_col[k]
            force = (tau[col] + model.servo[k, 1] * (gear * y[model.qrow[k]])
                     + model.servo[k, 2] * (gear * y[i_vel + col]))
            out[col] = gear * min(max(force, model.servo[k, 3]), model.servo[k, 4])


@_njit_inline
def servo_offset(work, flags):
    """Where the servos' moments (N floats) start in a workspace: before the springs'."""
    return work.shape[0] - flags[6] * (1 + (flags[FLAG_SPRINGS] != 0))


@_njit_inline
def motor_offset(work, flags, n):
    """Where the motors' terms (n, 4) start in a workspace: before the servos' and springs'."""
    return work.shape[0] - flags[6] * ((flags[FLAG_SERVOS] != 0) + (flags[FLAG_SPRINGS] != 0)) - 4 * n


@_njit_inline
def motor_axes(model, R, motor_w):
    """motor_w (n, 4): each hinge's geared motor's m = J G a in world axes (a, the rotor's axis, is
    fixed in the parent: R^{k-1} a) and J G^2; zero rows where none (reference.positions'
    `motor_w`)."""
    motor = model.motor
    tree = model.parent.shape[0] != 0
    for k in range(motor.shape[0]):
        for r in range(4):
            motor_w[k, r] = 0.0
        kp = model.parent[k] if tree else k - 1
        if kp >= 0 and motor[k, 1] != 0.0:
            for r in range(3):
                motor_w[k, r] = motor[k, 0] * (R[kp, r, 0] * motor[k, 2] + R[kp, r, 1] * motor[k, 3]
                                               + R[kp, r, 2] * motor[k, 4])
            motor_w[k, 3] = motor[k, 1]


@_njit_inline
def motor_gyroscopic(y, model, w, motor_w, pb):
    """pb[k - 1] += w^{k-1} x (m phi_k'): the rotor's spin relative to its carrier, J G phi_k' a,
    is the parent's gyrostatic moment (eq 31); its rate in the parent's axes, m phi_k'', is the
    elimination's (`_motor_column`)."""
    i_vel = model.flags[4]
    tree = model.parent.shape[0] != 0
    for k in range(1, motor_w.shape[0]):
        if motor_w[k, 3] != 0.0:  # (a motor on a body on the base is an armature: its row is zero)
            kp = model.parent[k] if tree else k - 1
            rate = y[i_vel + model.own_col[k]]
            l0, l1, l2 = motor_w[k, 0] * rate, motor_w[k, 1] * rate, motor_w[k, 2] * rate
            pb[kp, 0] += w[kp, 1] * l2 - w[kp, 2] * l1
            pb[kp, 1] += w[kp, 2] * l0 - w[kp, 0] * l2
            pb[kp, 2] += w[kp, 0] * l1 - w[kp, 1] * l0


@_njit_inline
def _spring_moments(y, model, tau, out):
    """out (N,): the generalized forces tau with the hinges' spring moments -k (phi - phi_ref)
    added (gyro_sim.dynamics.reference.spring_moments)."""
    for j in range(tau.shape[0]):
        out[j] = tau[j]
    for k in range(model.mass.shape[0]):
        if model.is_hinge[k]:
            out[model.own_col[k]] += -model.spring[k, 0] * (y[model.qrow[k]] - model.spring[k, 1])


@_njit
def normalize_quaternions(y, i_q0, nq):
    """Quaternions y[i_q0 + 4 j : i_q0 + 4 j + 4], j < nq, to unit length in place."""
    for j in range(nq):
        i = i_q0 + 4 * j
        nrm = math.sqrt(y[i] * y[i] + y[i + 1] * y[i + 1] + y[i + 2] * y[i + 2] + y[i + 3] * y[i + 3])
        for a in range(4):
            y[i + a] /= nrm


# --- the kernel's records --------------------------------------------------------------------
def chain_model(model: Model) -> ChainModel:
    """The model as the compiled kernels read it (see ChainModel).

    Per body: the y index of its quaternion (spherical) or of phi_k (hinge) or d_k (slide) (`qrow`); the first
    velocity column of its own joint (`own_col`); the range of all its columns (`col_start`,
    n + 1; a free base's translations belong to body 0). `flags` and `base` as in `rhs_kernel`:
    the kernel's C function is compiled (or loaded) now, and the heavy path for a model with
    heavy subtrees (`heavy_subtrees`).
    """
    m, n = model, model.n
    qrow = np.empty(n, dtype=np.int64)
    qrow[m.sph_bodies] = m.i_quat[:, 0]
    qrow[m.hinge_bodies] = m.i_phi.start + np.arange(len(m.hinge_bodies))
    own_col = np.empty(n, dtype=np.int64)
    own_col[m.sph_bodies] = m.col_sph[:, 0]
    own_col[m.hinge_bodies] = m.col_hinge
    col_start = np.searchsorted(m.col_body, np.arange(n + 1)).astype(np.int64)
    if np.any(np.diff(col_start) > MAX_JOINT_DOF):
        raise ValueError("a joint has more than six velocity columns")
    base_type = {"fixed": BASE_FIXED, "moving": BASE_MOVING, "free": BASE_FREE}[m.base_type]
    has_lam = len(m.torque_body) > 0 or m.lam_speed is not None
    tree = not m.chain
    heavy = heavy_elimination_address() if heavy_subtrees(m.mass, m.parent if tree else None) else 0
    flags = np.array([base_type, m.gravity is not None, has_lam, m.i_r0.start, m.i_vel.start,
                      m.i_kappa.start, m.N, heavy, kernel_address(), int(m.stateful), m.i_spin.start,
                      m.i_work.start, m.spring is not None, m.servo is not None, m.motor is not None, tree],
                     dtype=np.int64)
    base = np.zeros(7)
    if m.base_amplitude is not None:
        base[0:3] = m.base_amplitude
    base[3] = m.base_omega
    if m.gravity is not None:
        base[4:7] = m.gravity
    nt = len(m.torque_body)
    armature = np.zeros(n)
    spring = np.zeros((n, 2))
    if m.armature is not None:
        armature[m.hinge_bodies] = m.armature
    if m.spring is not None:
        spring[m.hinge_bodies] = m.spring
    servo = np.zeros((n, 5))
    if m.servo is not None:
        servo[m.hinge_bodies[m.servo_hinge]] = m.servo
    motor = np.zeros((n, 5))
    if m.motor is not None:  # J G, J G^2, a
        J, G = m.motor[:, 0], m.motor[:, 1]
        motor[m.hinge_bodies] = np.column_stack((J * G, J * G * G, m.motor[:, 2:]))

    def f64(a, shape):
        return np.ascontiguousarray(np.asarray(a, dtype=np.float64).reshape(shape))

    return ChainModel(
        is_hinge=np.ascontiguousarray(m.is_hinge, dtype=np.bool_),
        qrow=qrow,
        own_col=own_col,
        col_start=col_start,
        hinge_axis=f64(m.hinge_axis, (n, 3)),
        s=f64(m.offset if tree else m.s, (n, 3)),
        mass=f64(m.mass, (n,)),
        first_moment=f64(m.first_moment, (n, 3)),
        inertia=f64(m.inertia, (n, 3, 3)),
        lam_speed=f64(np.zeros((n, 3)) if m.lam_speed is None else m.lam_speed, (n, 3)),
        torque_body=np.ascontiguousarray(m.torque_body, dtype=np.int64),
        torque_axis=f64(m.torque_axis, (nt, 3)),
        torque_A=f64(m.torque_A, (nt,)),
        flags=flags,
        base=base,
        armature=armature,
        spring=spring,
        servo=servo,
        motor=motor,
        is_slide=np.ascontiguousarray(m.is_slide, dtype=np.bool_),
        parent=np.ascontiguousarray(m.parent if tree else np.zeros(0), dtype=np.int64),
    )


def held_inputs(model: Model, t0: float = 0.0, p0=None, hinge_tau=None, L_rotor=None) -> HeldInputs:
    """New held inputs of `model` (see HeldInputs and `hold`); None stands for zeros."""
    nt = len(model.torque_body)
    inputs = HeldInputs(np.zeros(1), np.zeros(nt), np.zeros(nt), np.zeros(nt), np.zeros(model.N))
    hold(inputs, model, t0, p0, hinge_tau, L_rotor)
    return inputs


def hold(inputs: HeldInputs, model: Model, t0: float, p0, hinge_tau, L_rotor) -> None:
    """Write into `inputs`, in place: t0, the spins p0 (nt,) at t0, pdot = L / A, the torques
    L_rotor (nt,), tau (N,) with the hinge moments in the hinges' columns; None stands for
    zeros."""
    m = model
    nt = len(m.torque_body)
    inputs.t0[0] = float(t0)
    inputs.p0[:] = 0.0 if p0 is None else np.asarray(p0, dtype=np.float64).reshape(nt)
    inputs.L_rotor[:] = 0.0 if L_rotor is None else np.asarray(L_rotor, dtype=np.float64).reshape(nt)
    inputs.pdot[:] = inputs.L_rotor / m.torque_A if nt else 0.0
    inputs.tau[:] = 0.0
    if hinge_tau is not None:
        inputs.tau[m.col_hinge] = hinge_tau  # (51): e^k . L^k = L_k


def scratch(model: Model) -> np.ndarray:
    """The float scratch of `rhs_kernel`: n WORK_PER_BODY + N WORK_PER_COLUMN
    + nt WORK_PER_ROTOR + WORK_FIXED (nt torque rotors). A stateful model (`Model.stateful`)
    appends its actuators' parameters, ACTUATOR_PARAMETERS per torque rotor then per body
    (hinges'; zero on spherical bodies), and the scratch of the applied torques (nt + N). A model
    with hinge springs appends N floats for the generalized forces with their moments. A model
    with geared motors has 4 n floats before the servos' and springs' (`motor_offset`)."""
    m, nt = model, len(model.torque_body)
    size = m.n * WORK_PER_BODY + m.N * WORK_PER_COLUMN + nt * WORK_PER_ROTOR + WORK_FIXED
    springs = np.zeros(4 * m.n * (m.motor is not None) + m.N * ((m.spring is not None) + (m.servo is not None)))
    if not m.stateful:
        return np.zeros(size + len(springs))
    act = m.actuators
    hinge = np.zeros((m.n, ACTUATOR_PARAMETERS))
    hinge[:, 0] = np.inf
    hinge[:, 5] = 1.0
    hinge[m.hinge_bodies] = _axis_parameters(act.hinge)
    return np.concatenate((np.zeros(size), _axis_parameters(act.rotor).ravel(), hinge.ravel(), np.zeros(nt + m.N),
                           springs))


def workspace(model: Model, chain: ChainModel, inputs: HeldInputs) -> Workspace:
    """A new workspace for `chain` (of `model`) and `inputs`: its scratch, and its descriptor of
    all three (`describe`). The three stay bound: pass them together."""
    data = Workspace(scratch(model), np.zeros(DESCRIPTOR_SIZE, dtype=np.int64))
    describe(chain, data, inputs)
    return data


def describe(chain: ChainModel, data: Workspace, inputs: HeldInputs) -> None:
    """Write into data.descriptor where the kernel's C function finds `chain`, `data` and
    `inputs` (the one place its layout is written; `records_at` reads it): the arrays'
    addresses, n, N, nt, the scratch's size; the evaluations counted start at 0. The arrays
    must be C-contiguous and stay alive and in place as long as the descriptor is used."""
    arrays = (*chain, data.work, *inputs)
    if not all(a.flags.c_contiguous for a in arrays):
        raise ValueError("the kernel's arrays must be C-contiguous")
    d = data.descriptor
    d[D_MODEL:D_MODEL + len(chain)] = [a.ctypes.data for a in chain]
    d[D_WORK] = data.work.ctypes.data
    d[D_INPUTS:D_INPUTS + len(inputs)] = [a.ctypes.data for a in inputs]
    d[D_N], d[D_NCOL], d[D_NT] = len(chain.mass), len(inputs.tau), len(chain.torque_body)
    d[D_NWORK], d[D_NFEV] = len(data.work), 0


def records(model: Model) -> tuple[ChainModel, Workspace, HeldInputs]:
    """(model, data, inputs) of `model` as the compiled kernels take them, bound together, the
    inputs held at zero from t0 = 0 (`hold` writes others in place)."""
    chain, inputs = chain_model(model), held_inputs(model)
    return chain, workspace(model, chain, inputs), inputs


def _axis_parameters(limits) -> np.ndarray:
    """(axes, ACTUATOR_PARAMETERS) of gyro_sim.dynamics.actuators.AxisLimits."""
    return np.stack((limits.max_speed, limits.coulomb, limits.viscous, limits.static, limits.stribeck_speed,
                     limits.stick_speed), axis=1).reshape(-1, ACTUATOR_PARAMETERS)


# --- the stages other compiled modules build on (fast_canonical: the canonical field) ---------
#: inlined there as here; the same dispatchers under public names
positions_stage = body_positions
spatial_inertia = _spatial_inertia
velocities_stage = body_velocities
joint_columns_stage = _joint_columns
articulated_solve = _aba
quat_rate = _quat_rate
rotor_angle_rate = _rotor_angle_rate
