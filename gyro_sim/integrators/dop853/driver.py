"""The Dormand-Prince 8(5,3) pair (dop853): order 8, adaptive, dense output of order 7."""
from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from gyro_sim.integrators.adaptive_kernels import clip_step
from gyro_sim.integrators.dop853 import loop as fast_dop853
from gyro_sim.integrators.dop853.kernels import (
    CONTROL_SIZE, INITIAL_SIZE, NO_HLAMB, dop_control, dop_dense_coefficients,
    dop_dense_eval, dop_error_norm, dop_finite, dop_hlamb, dop_initial_probe, dop_initial_step,
    dop_stage_state, dop_update,
)
from gyro_sim.integrators.base import (
    H0_DEFAULT, H0_FRACTION, H0_GROWTH, H0_NEGLIGIBLE, H0_TINY_DERIVATIVES, H0_TINY_FRACTION,
    H0_TINY_STEP, LAST_STEP_STRETCH, MAX_FACTOR, MIN_FACTOR, MIN_STEP_RELATIVE, SAFETY,
    AdaptiveIntegrator, ExplicitRungeKutta, IntegrationError, WholeAdvanceLoop, describe_nonfinite,
)

if TYPE_CHECKING:
    from gyro_sim.dynamics.system import OdeSystem

# --- DOP853 coefficients ------------------------------------------------------------------
# Copied from scipy/integrate/_ivp/dop853_coefficients.py (scipy 1.17, BSD-3-Clause), which
# takes them from Hairer's dop853.f. Rows 0..11 of A are the stages, row 12 (= B) gives the
# FSAL stage f(t + h, y1), rows 13..15 the three extra stages of the dense output.
_DOP_N_STAGES = 12
_DOP_N_EXTENDED = 16
_DOP_N_DENSE = 7

_DOP_C = np.array([0.0,
                   0.526001519587677318785587544488e-01,
                   0.789002279381515978178381316732e-01,
                   0.118350341907227396726757197510,
                   0.281649658092772603273242802490,
                   0.333333333333333333333333333333,
                   0.25,
                   0.307692307692307692307692307692,
                   0.651282051282051282051282051282,
                   0.6,
                   0.857142857142857142857142857142,
                   1.0,
                   1.0,
                   0.1,
                   0.2,
                   0.777777777777777777777777777778])

_DOP_A = np.zeros((_DOP_N_EXTENDED, _DOP_N_EXTENDED))
_DOP_A[1, 0] = 5.26001519587677318785587544488e-2

_DOP_A[2, 0] = 1.97250569845378994544595329183e-2
_DOP_A[2, 1] = 5.91751709536136983633785987549e-2

_DOP_A[3, 0] = 2.95875854768068491816892993775e-2
_DOP_A[3, 2] = 8.87627564304205475450678981324e-2

_DOP_A[4, 0] = 2.41365134159266685502369798665e-1
_DOP_A[4, 2] = -8.84549479328286085344864962717e-1
_DOP_A[4, 3] = 9.24834003261792003115737966543e-1

_DOP_A[5, 0] = 3.7037037037037037037037037037e-2
_DOP_A[5, 3] = 1.70828608729473871279604482173e-1
_DOP_A[5, 4] = 1.25467687566822425016691814123e-1

_DOP_A[6, 0] = 3.7109375e-2
_DOP_A[6, 3] = 1.70252211019544039314978060272e-1
_DOP_A[6, 4] = 6.02165389804559606850219397283e-2
_DOP_A[6, 5] = -1.7578125e-2

_DOP_A[7, 0] = 3.70920001185047927108779319836e-2
_DOP_A[7, 3] = 1.70383925712239993810214054705e-1
_DOP_A[7, 4] = 1.07262030446373284651809199168e-1
_DOP_A[7, 5] = -1.53194377486244017527936158236e-2
_DOP_A[7, 6] = 8.27378916381402288758473766002e-3

_DOP_A[8, 0] = 6.24110958716075717114429577812e-1
_DOP_A[8, 3] = -3.36089262944694129406857109825
_DOP_A[8, 4] = -8.68219346841726006818189891453e-1
_DOP_A[8, 5] = 2.75920996994467083049415600797e1
_DOP_A[8, 6] = 2.01540675504778934086186788979e1
_DOP_A[8, 7] = -4.34898841810699588477366255144e1

_DOP_A[9, 0] = 4.77662536438264365890433908527e-1
_DOP_A[9, 3] = -2.48811461997166764192642586468
_DOP_A[9, 4] = -5.90290826836842996371446475743e-1
_DOP_A[9, 5] = 2.12300514481811942347288949897e1
_DOP_A[9, 6] = 1.52792336328824235832596922938e1
_DOP_A[9, 7] = -3.32882109689848629194453265587e1
_DOP_A[9, 8] = -2.03312017085086261358222928593e-2

_DOP_A[10, 0] = -9.3714243008598732571704021658e-1
_DOP_A[10, 3] = 5.18637242884406370830023853209
_DOP_A[10, 4] = 1.09143734899672957818500254654
_DOP_A[10, 5] = -8.14978701074692612513997267357
_DOP_A[10, 6] = -1.85200656599969598641566180701e1
_DOP_A[10, 7] = 2.27394870993505042818970056734e1
_DOP_A[10, 8] = 2.49360555267965238987089396762
_DOP_A[10, 9] = -3.0467644718982195003823669022

_DOP_A[11, 0] = 2.27331014751653820792359768449
_DOP_A[11, 3] = -1.05344954667372501984066689879e1
_DOP_A[11, 4] = -2.00087205822486249909675718444
_DOP_A[11, 5] = -1.79589318631187989172765950534e1
_DOP_A[11, 6] = 2.79488845294199600508499808837e1
_DOP_A[11, 7] = -2.85899827713502369474065508674
_DOP_A[11, 8] = -8.87285693353062954433549289258
_DOP_A[11, 9] = 1.23605671757943030647266201528e1
_DOP_A[11, 10] = 6.43392746015763530355970484046e-1

_DOP_A[12, 0] = 5.42937341165687622380535766363e-2
_DOP_A[12, 5] = 4.45031289275240888144113950566
_DOP_A[12, 6] = 1.89151789931450038304281599044
_DOP_A[12, 7] = -5.8012039600105847814672114227
_DOP_A[12, 8] = 3.1116436695781989440891606237e-1
_DOP_A[12, 9] = -1.52160949662516078556178806805e-1
_DOP_A[12, 10] = 2.01365400804030348374776537501e-1
_DOP_A[12, 11] = 4.47106157277725905176885569043e-2

_DOP_A[13, 0] = 5.61675022830479523392909219681e-2
_DOP_A[13, 6] = 2.53500210216624811088794765333e-1
_DOP_A[13, 7] = -2.46239037470802489917441475441e-1
_DOP_A[13, 8] = -1.24191423263816360469010140626e-1
_DOP_A[13, 9] = 1.5329179827876569731206322685e-1
_DOP_A[13, 10] = 8.20105229563468988491666602057e-3
_DOP_A[13, 11] = 7.56789766054569976138603589584e-3
_DOP_A[13, 12] = -8.298e-3

_DOP_A[14, 0] = 3.18346481635021405060768473261e-2
_DOP_A[14, 5] = 2.83009096723667755288322961402e-2
_DOP_A[14, 6] = 5.35419883074385676223797384372e-2
_DOP_A[14, 7] = -5.49237485713909884646569340306e-2
_DOP_A[14, 10] = -1.08347328697249322858509316994e-4
_DOP_A[14, 11] = 3.82571090835658412954920192323e-4
_DOP_A[14, 12] = -3.40465008687404560802977114492e-4
_DOP_A[14, 13] = 1.41312443674632500278074618366e-1

_DOP_A[15, 0] = -4.28896301583791923408573538692e-1
_DOP_A[15, 5] = -4.69762141536116384314449447206
_DOP_A[15, 6] = 7.68342119606259904184240953878
_DOP_A[15, 7] = 4.06898981839711007970213554331
_DOP_A[15, 8] = 3.56727187455281109270669543021e-1
_DOP_A[15, 12] = -1.39902416515901462129418009734e-3
_DOP_A[15, 13] = 2.9475147891527723389556272149
_DOP_A[15, 14] = -9.15095847217987001081870187138

_DOP_B = _DOP_A[_DOP_N_STAGES, :_DOP_N_STAGES].copy()

_DOP_E3 = np.zeros(_DOP_N_STAGES + 1)
_DOP_E3[:-1] = _DOP_B
_DOP_E3[0] -= 0.244094488188976377952755905512
_DOP_E3[8] -= 0.733846688281611857341361741547
_DOP_E3[11] -= 0.220588235294117647058823529412e-1

_DOP_E5 = np.zeros(_DOP_N_STAGES + 1)
_DOP_E5[0] = 0.1312004499419488073250102996e-1
_DOP_E5[5] = -0.1225156446376204440720569753e+1
_DOP_E5[6] = -0.4957589496572501915214079952
_DOP_E5[7] = 0.1664377182454986536961530415e+1
_DOP_E5[8] = -0.3503288487499736816886487290
_DOP_E5[9] = 0.3341791187130174790297318841
_DOP_E5[10] = 0.8192320648511571246570742613e-1
_DOP_E5[11] = -0.2235530786388629525884427845e-1

# Dense output: rows 3..6 of the interpolant; rows 0..2 come from y_old, y_new, f_old, f_new.
_DOP_D = np.zeros((_DOP_N_DENSE - 3, _DOP_N_EXTENDED))
_DOP_D[0, 0] = -0.84289382761090128651353491142e+1
_DOP_D[0, 5] = 0.56671495351937776962531783590
_DOP_D[0, 6] = -0.30689499459498916912797304727e+1
_DOP_D[0, 7] = 0.23846676565120698287728149680e+1
_DOP_D[0, 8] = 0.21170345824450282767155149946e+1
_DOP_D[0, 9] = -0.87139158377797299206789907490
_DOP_D[0, 10] = 0.22404374302607882758541771650e+1
_DOP_D[0, 11] = 0.63157877876946881815570249290
_DOP_D[0, 12] = -0.88990336451333310820698117400e-1
_DOP_D[0, 13] = 0.18148505520854727256656404962e+2
_DOP_D[0, 14] = -0.91946323924783554000451984436e+1
_DOP_D[0, 15] = -0.44360363875948939664310572000e+1

_DOP_D[1, 0] = 0.10427508642579134603413151009e+2
_DOP_D[1, 5] = 0.24228349177525818288430175319e+3
_DOP_D[1, 6] = 0.16520045171727028198505394887e+3
_DOP_D[1, 7] = -0.37454675472269020279518312152e+3
_DOP_D[1, 8] = -0.22113666853125306036270938578e+2
_DOP_D[1, 9] = 0.77334326684722638389603898808e+1
_DOP_D[1, 10] = -0.30674084731089398182061213626e+2
_DOP_D[1, 11] = -0.93321305264302278729567221706e+1
_DOP_D[1, 12] = 0.15697238121770843886131091075e+2
_DOP_D[1, 13] = -0.31139403219565177677282850411e+2
_DOP_D[1, 14] = -0.93529243588444783865713862664e+1
_DOP_D[1, 15] = 0.35816841486394083752465898540e+2

_DOP_D[2, 0] = 0.19985053242002433820987653617e+2
_DOP_D[2, 5] = -0.38703730874935176555105901742e+3
_DOP_D[2, 6] = -0.18917813819516756882830838328e+3
_DOP_D[2, 7] = 0.52780815920542364900561016686e+3
_DOP_D[2, 8] = -0.11573902539959630126141871134e+2
_DOP_D[2, 9] = 0.68812326946963000169666922661e+1
_DOP_D[2, 10] = -0.10006050966910838403183860980e+1
_DOP_D[2, 11] = 0.77771377980534432092869265740
_DOP_D[2, 12] = -0.27782057523535084065932004339e+1
_DOP_D[2, 13] = -0.60196695231264120758267380846e+2
_DOP_D[2, 14] = 0.84320405506677161018159903784e+2
_DOP_D[2, 15] = 0.11992291136182789328035130030e+2

_DOP_D[3, 0] = -0.25693933462703749003312586129e+2
_DOP_D[3, 5] = -0.15418974869023643374053993627e+3
_DOP_D[3, 6] = -0.23152937917604549567536039109e+3
_DOP_D[3, 7] = 0.35763911791061412378285349910e+3
_DOP_D[3, 8] = 0.93405324183624310003907691704e+2
_DOP_D[3, 9] = -0.37458323136451633156875139351e+2
_DOP_D[3, 10] = 0.10409964950896230045147246184e+3
_DOP_D[3, 11] = 0.29840293426660503123344363579e+2
_DOP_D[3, 12] = -0.43533456590011143754432175058e+2
_DOP_D[3, 13] = 0.96324553959188282948394950600e+2
_DOP_D[3, 14] = -0.39177261675615439165231486172e+2
_DOP_D[3, 15] = -0.14972683625798562581422125276e+3


class DOP853(ExplicitRungeKutta, WholeAdvanceLoop, AdaptiveIntegrator):
    """Explicit Runge-Kutta method of order 8 with error control and dense output.

    The Dormand-Prince 8(5,3) pair as in Hairer's dop853.f (HNW I, sec. II.10): 12 stages (the
    13th, FSAL, is the next step's first), an error estimate combining the 5th- and 3rd-order
    embedded formulas (err = h |e5|^2 / sqrt(|e5|^2 + 0.01 |e3|^2), RMS-weighted, as scipy's
    DOP853), and a dense output of order 7 (sec. II.6) that costs 3 more rhs evaluations in the
    steps where it is asked for. Step control (sec. II.4): h_new = h min(MAX_FACTOR, SAFETY
    err^(-1/8)), at most h after a rejection, h max(MIN_FACTOR, SAFETY err^(-1/8)) for a rejected
    step, h MIN_FACTOR after a non-finite trial. The first step: `AdaptiveIntegrator._initial_step`.

    One implementation, two drivers: the arithmetic (stage states, the step, the error norm,
    the controller, the dense output) is :mod:`gyro_sim.integrators.dop853.kernels`. On a system that
    offers `kernel_arguments` and `quaternion_block` (the compiled
    :class:`gyro_sim.dynamics.system.FastChainODE`) a whole `advance` runs in one compiled call,
    :func:`gyro_sim.integrators.dop853.loop.dop853_advance`, with this class's tableau (the loop is
    compiled, or loaded from numba's cache, when the integrator is built: ~12 s of CPU once
    per version of its files, then ~0.1 s); on any other system, and for the public single
    step (`begin` / `take_step` / `dense`, which the "auto" method drives on systems without
    the compiled loop), this class steps in Python, calling the same arithmetic between its
    rhs evaluations. The two give the same bits, counters included; against scipy's DOP853 on
    the same rhs they take the same steps (times equal to ~1e-9 relative: the round-off of the
    error norm's cancelling sums, through err^(-1/8)) with states equal to round-off
    (test/core/test_fast_dop853.py). The starting step is `AdaptiveIntegrator._initial_step`'s,
    in the kernels' arithmetic.

    With `stiffness_estimate=True`, each accepted step also gets dop853.f's estimate of
    h |lambda| (HLAMB), h ||f(y1) - f(Y12)|| / ||y1 - Y12|| (Y12 the last stage, at t + h): the
    step times the dominant eigenvalue along it (dop853_kernels.dop_hlamb). It needs f(y1), so
    it is ready after the `take_step` or `dense` that evaluates f(y1), or, for the last step of
    a call, after the next call's `begin` if that call continues from the step's end. `hlamb`
    holds it until the next `begin` or `take_step` (None: not ready, or y1 = Y12). `advance`
    of such an integrator steps in Python; the "auto" method's tests on these estimates run
    in the compiled loop too (its detection mode, :meth:`_integrate_compiled` with
    `detection`), with the same estimates, held from call to call in the same way.

    References
    ----------
    .. [1] E. Hairer, S. P. Norsett, G. Wanner, "Solving Ordinary Differential Equations I:
           Nonstiff Problems", 2nd ed., Springer 1993, sec. II.4 (step control), II.5, II.6
           (dense output) and II.10 (DOP853).
    .. [2] E. Hairer, dop853.f, http://www.unige.ch/~hairer/software.html
    .. [3] scipy.integrate.DOP853 (scipy/integrate/_ivp/rk.py): the error norm and the
           dense-output evaluation are ported from there.
    """

    name = "dop853"
    order = 8
    error_estimator_order = 7
    dense_output = True
    n_stages = _DOP_N_STAGES
    A = _DOP_A[:_DOP_N_STAGES, :_DOP_N_STAGES]
    B = _DOP_B
    C = _DOP_C[:_DOP_N_STAGES]
    #: the two embedded error estimators (stage 12, the FSAL stage, has weight 0 in both)
    E3 = _DOP_E3[:_DOP_N_STAGES]
    E5 = _DOP_E5[:_DOP_N_STAGES]
    E = E5
    #: dense output: extra stages 13..15 and the interpolant rows 3..6
    A_EXTRA = _DOP_A[_DOP_N_STAGES + 1:]
    C_EXTRA = _DOP_C[_DOP_N_STAGES + 1:]
    D = _DOP_D
    #: the extended tableau the kernels read: rows 0..11 the stages, 12 the weights B (the
    #: FSAL stage), 13..15 the extra stages of the dense output
    A_ALL = _DOP_A
    C_ALL = _DOP_C
    #: the controller's constants (dop853_kernels.dop_control): SAFETY, MIN_FACTOR, MAX_FACTOR,
    #: the exponent -1/(q + 1) of the order-q = 7 estimator, MIN_STEP_RELATIVE, LAST_STEP_STRETCH
    CONTROL = np.array([SAFETY, MIN_FACTOR, MAX_FACTOR, -1.0 / (7 + 1), MIN_STEP_RELATIVE,
                        LAST_STEP_STRETCH])
    #: the starting step's constants (dop853_kernels.dop_initial_probe, dop_initial_step), base's
    INITIAL = np.array([H0_NEGLIGIBLE, H0_DEFAULT, H0_FRACTION, H0_GROWTH, H0_TINY_DERIVATIVES,
                        H0_TINY_STEP, H0_TINY_FRACTION])
    assert CONTROL.size == CONTROL_SIZE and INITIAL.size == INITIAL_SIZE

    def __init__(self, system: OdeSystem, *, stiffness_estimate: bool = False, **options):
        super().__init__(system, **options)
        n = self.n
        self.stiffness_estimate = stiffness_estimate
        #: h |lambda| of an accepted step (see the class docstring), or None
        self.hlamb: float | None = None
        self._pending = None  # (t1, y1, h, Y12, f(Y12)) of a step whose f(y1) is not known yet
        self._K = np.zeros((_DOP_N_EXTENDED, n))
        self._ys = np.zeros(n)
        self._F = np.zeros((_DOP_N_DENSE, n))
        self._atol_v = np.ascontiguousarray(np.broadcast_to(np.asarray(self.atol, dtype=float), (n,)))
        self._C_all = _DOP_C
        self._A_all = _DOP_A
        self._h = 0.0  # the accepted step (for the dense output)
        # the compiled loop (fast_dop853), when the system offers the kernel
        self._loop = None
        if n and callable(getattr(system, "kernel_arguments", None)) and callable(
                getattr(system, "quaternion_block", None)):
            self._loop = fast_dop853.loop_for(system.kernel_arguments())
            self._i_q0, self._nq = (int(v) for v in system.quaternion_block())
            self._real = np.zeros(fast_dop853.REAL_SIZE)
            self._status = np.zeros(fast_dop853.STATUS_SIZE, dtype=np.int64)
            self._bad = np.zeros(_DOP_N_STAGES, dtype=np.int64)
            self._no_te, self._no_Y = np.zeros(0), np.zeros((0, n))
            #: the ends of the first len(_trace) accepted steps of the last compiled call (tests)
            self._trace = np.zeros(0)
            # the detection mode's step held for the next call (fast_dop853: held, held_at)
            self._held = np.zeros((3, n))
            self._held_at = np.array([math.nan, 0.0])
            #: outputs filled by the last compiled call (also when it raised)
            self.outputs_filled = 0
            # compile (or load) the loop now, not in the first advance: a call of no step from
            # a valid state (unit quaternions)
            y = np.zeros(n)
            y[self._i_q0:self._i_q0 + 4 * self._nq:4] = 1.0
            self._call_loop(0.0, y, 0.0, self._no_te, self._no_Y, 1.0, _NO_DETECTION)
            self._f[:] = 0.0

    # --- the Python driver ---------------------------------------------------------------------
    def _initial_step(self, t0, y0, f0, t1, order) -> float:
        """The starting step (HNW I, sec. II.4; scipy's select_initial_step) by the kernels the
        compiled loop calls: `AdaptiveIntegrator._initial_step` in the same arithmetic."""
        if self.n == 0:
            return super()._initial_step(t0, y0, f0, t1, order)
        span = t1 - t0
        sc, y1 = np.empty(self.n), np.empty(self.n)
        h0, d1 = dop_initial_probe(y0, f0, self.rtol, self._atol_v, span, self.INITIAL, sc, y1)
        f1 = self._fun(t0 + h0, y1)
        return dop_initial_step(f0, f1, sc, h0, d1, span, self.max_step, order, self.INITIAL)

    def _step_impl(self, t: float, y: np.ndarray, t1: float) -> float:
        K, ys, y_new, A, C = self._K, self._ys, self._y_new, self._A_all, self._C_all
        h_abs = min(self._h_abs, self.max_step)
        min_step = self._min_step(t, t1)
        rejected = False
        nonfinite = ""
        while True:
            if h_abs < min_step:
                raise self._collapse(t, h_abs, nonfinite)
            h, t_new = clip_step(t, h_abs, t1, LAST_STEP_STRETCH)
            K[0] = self._f
            for s in range(1, _DOP_N_STAGES):
                dop_stage_state(y, K, A, s, h, ys)  # ys = y + (sum_j A[s, j] K[j]) h
                K[s] = self._fun(t + C[s] * h, ys)
            dop_update(y, K, self.B, h, y_new)  # y1 = y + h sum_i B_i K_i
            error_norm = dop_error_norm(K, self.E5, self.E3, h, y, y_new, self.rtol, self._atol_v)
            finite = dop_finite(y_new)
            accepted, h_next = dop_control(error_norm, finite, h, h_abs, rejected, self.CONTROL)
            if accepted:
                self._h_abs = h_next
                break
            if not (finite and math.isfinite(error_norm)):
                nonfinite = describe_nonfinite(K[:_DOP_N_STAGES])
            h_abs = h_next
            rejected = True
            self.nrejected += 1
        self.error_estimate = error_norm
        self.last_step = self._h = h
        return t_new

    def reset(self) -> None:
        super().reset()
        self.hlamb = None
        self._pending = None
        if self._loop is not None:
            self._held_at[fast_dop853.H_T] = math.nan

    def begin(self, t0: float, y: np.ndarray, t1: float) -> None:
        self.hlamb = None
        super().begin(t0, y, t1)
        if self._pending is not None:
            t_p, y_p, h, Y12, f12 = self._pending
            self._pending = None
            if t_p == t0 and np.array_equal(y_p, y):  # a continuation: f(y1) is the fresh rhs
                self.hlamb = self._hlamb(h, Y12, f12, y, self._f)

    def take_step(self, t: float, y: np.ndarray, t1: float) -> float:
        self.hlamb = None
        t_new = super().take_step(t, y, t1)
        if self.stiffness_estimate and not self._f_new:  # the estimate waits for f(y1)
            self._pending = (t_new, self._y_new.copy(), self._h, self._ys.copy(),
                             self._K[_DOP_N_STAGES - 1].copy())
        return t_new

    def _rhs_at_new(self, t_new: float, y_new: np.ndarray) -> None:
        super()._rhs_at_new(t_new, y_new)
        self._K[_DOP_N_STAGES] = self._f  # the FSAL stage
        if self.stiffness_estimate:  # _ys still holds Y12 and K[11] f(t + h, Y12)
            self._pending = None
            self.hlamb = self._hlamb(self._h, self._ys, self._K[_DOP_N_STAGES - 1], y_new, self._f)

    @staticmethod
    def _hlamb(h: float, Y12: np.ndarray, f12: np.ndarray, y1: np.ndarray, f1: np.ndarray):
        """dop853.f's h |lambda| ~ |h| ||f1 - f12|| / ||y1 - Y12|| (dop853_kernels.dop_hlamb,
        as the compiled loop's detection mode); None if y1 = Y12."""
        hlamb = dop_hlamb(h, Y12, f12, y1, f1)
        return None if hlamb == NO_HLAMB else hlamb

    def _dense(self, t, y, t_new, y_new, tq: np.ndarray) -> np.ndarray:
        K, ys, h, A, C = self._K, self._ys, self._h, self._A_all, self._C_all
        for s in range(_DOP_N_STAGES + 1, _DOP_N_EXTENDED):  # the three extra stages
            dop_stage_state(y, K, A, s, h, ys)
            K[s] = self._fun(t + C[s] * h, ys)
        dop_dense_coefficients(y, y_new, K, self.D, h, self._F)
        tq = np.ascontiguousarray(tq, dtype=float)
        out = np.empty((tq.size, self.n))
        dop_dense_eval(self._F, y, t, h, tq, out)
        return out

    # --- the compiled loop -------------------------------------------------------------------
    def _integrate(self, t0, y, t1, te, Y) -> None:
        if self._loop is None or self.stiffness_estimate or t1 == t0:
            super()._integrate(t0, y, t1, te, Y)
        else:
            self._integrate_compiled(t0, y, t1, te, Y)

    def _integrate_compiled(self, t0: float, y: np.ndarray, t1: float, te, Y,
                            detection: tuple | None = None) -> tuple[float, int]:
        """`_integrate` (the loop of `begin`, `take_step`, `dense`) in one compiled call.

        With `detection`, the arrays (detect, counters, attempts, window, cost) of
        dop853_kernels' stiffness detection, the loop runs in its detection mode
        (fast_dop853.dop853_advance) and may stop at an accepted state before t1: returns
        (the time reached, the reason of a switch asked for there, fast_dop853.REASON_*, or 0).
        `outputs_filled`: the rows of Y filled, also when the call raises.
        """
        fd = fast_dop853
        if te is None:
            te, Y = self._no_te, self._no_Y
        elif not (te.flags.c_contiguous and te.flags.writeable):
            te = te.copy()
        real, status = self._real, self._status
        real[fd.R_ERROR] = math.nan if self.error_estimate is None else self.error_estimate
        real[fd.R_LAST_STEP] = math.nan if self.last_step is None else self.last_step
        h_mem = 0.0 if self._h_abs is None else float(self._h_abs)  # 0: select the starting step
        self._call_loop(t0, y, t1, te, Y, h_mem, _NO_DETECTION if detection is None else detection)
        r, st = real.tolist(), status.tolist()
        self.outputs_filled = st[fd.S_OUTPUTS]
        nfev = st[fd.S_NFEV]
        self.nfev += nfev
        self.system.nfev += nfev
        self.nsteps += st[fd.S_ACCEPTED]
        self.nrejected += st[fd.S_REJECTED]
        self._h_abs = r[fd.R_H_ABS] if r[fd.R_H_ABS] > 0.0 else None
        if not math.isnan(r[fd.R_ERROR]):
            self.error_estimate = r[fd.R_ERROR]
            self.last_step = self._h = r[fd.R_LAST_STEP]
        self._f_new = st[fd.S_F_NEW] != 0
        code = st[fd.S_STATUS]
        if code == fd.DONE or code == fd.SWITCH:
            if st[fd.S_ACCEPTED]:
                self._t_old, self._t_new = r[fd.R_T_OLD], r[fd.R_T]
            return r[fd.R_T], st[fd.S_REASON]
        if code == fd.INITIAL_RHS_NONFINITE:
            raise IntegrationError(self.name, "rhs is not finite at the initial state", t0, None,
                                   describe_nonfinite(self._f))
        elif code == fd.COLLAPSED:
            nonfinite = ""
            if st[fd.S_NONFINITE]:  # the stages of the last non-finite trial, as named in Python
                nonfinite = describe_nonfinite(np.where(self._bad[:, None] != 0, np.nan, 0.0))
            raise self._collapse(r[fd.R_T], r[fd.R_H], nonfinite)
        else:  # ACCEPTED_RHS_NONFINITE
            raise IntegrationError(self.name, "rhs is not finite at the accepted state", r[fd.R_T],
                                   r[fd.R_H], describe_nonfinite(self._f))

    def _call_loop(self, t0: float, y: np.ndarray, t1: float, te, Y, h_mem: float,
                   detection: tuple) -> None:
        """fast_dop853.dop853_advance with this integrator's tableau, options and scratch."""
        self._loop(float(t0), float(t1), y, fast_dop853.Outputs(te, Y),
                   fast_dop853.Options(float(h_mem), float(self.max_step), float(self.rtol), self._atol_v,
                                       self._i_q0, self._nq),
                   fast_dop853.Method(self.A_ALL, self.C_ALL, self.E5, self.E3, self.D, self.CONTROL, self.INITIAL),
                   fast_dop853.State(self._f, self._K, self._ys, self._y_new, self._y_old, self._F, self._bad,
                                     self._trace, self._real, self._status, self._held, self._held_at),
                   fast_dop853.Detection(*detection), *self.system.kernel_arguments())


#: the detection arrays of a plain call (fast_dop853.dop853_advance: detect empty, the others
#: not read), of the types of Auto's
_NO_DETECTION = (np.zeros(0), np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64),
                 np.zeros((0, 2)), np.zeros(0))
