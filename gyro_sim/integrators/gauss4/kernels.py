"""The arithmetic of the gauss4 step (dense simplified Newton, or Newton-Krylov), compiled.

One implementation, two drivers, as :mod:`gyro_sim.integrators.rk4.kernels`:
:class:`gyro_sim.integrators.gauss4.driver.Gauss4` calls these between its rhs evaluations on any
system (the numpy reference among them), and the compiled loop
:func:`gyro_sim.integrators.gauss4.loop.gauss_march` calls the same functions between calls of the
articulated-body kernel. Every number either driver looks at (norms, rates, the decisions of
the stop tests, the pivots) comes out of these functions, so both take the same steps bit for
bit (test/integrators/test_gauss4.py).

The collocation equations of the 2-stage Gauss method for the stage increments Z (2, n)
(Hairer, Wanner II, sec. IV.8, eq. (8.2)):

    G(Z) = Z - (h A (x) I) F(Z) = 0,   F_s(Z) = f(t + c_s h, y + Z_s),   y1 = y + sum_s d_s Z_s

Newton: (I - h (A (x) I) diag(J_1, J_2)) dZ = -G(Z), J_s ~ f'(y + Z_s). Two ways to solve it:

- **dense** (systems up to a size threshold): the stage Jacobians J_s (2, n, n) by forward
  differences (`jac_perturb`, `jac_column`: n rhs evaluations per stage), the real iteration
  matrix M (2n, 2n) formed (`newton_matrix`) and factored by Gaussian elimination with
  partial pivoting (`lu_factor`), both kept across steps and reused (simplified Newton) until
  the iteration slows; each iteration is then 2 rhs evaluations and a solve (`lu_solve`,
  O(n^2)). The round-off floor of the iteration is measured when the matrix is formed
  (`noise_perturb`, `noise_residual`): the Newton update that a few-ulp change of the stage
  states makes, i.e. the noise of the rhs seen through M^-1.
- **Newton-Krylov** (above the threshold: O(n) memory): each linear system solved by GMRES
  (Saad-Schultz; Kelley, "Iterative Methods for Linear and Nonlinear Equations", SIAM 1995,
  sec. 3.4-3.5: Arnoldi by modified Gram-Schmidt, the least-squares problem by Givens
  rotations) on the operator applied without forming it: the products J_s v_s are forward
  differences of f in the direction v_s (Kelley, "Solving Nonlinear Equations with Newton's
  Method", SIAM 2003, sec. 3.2), two rhs evaluations per Krylov vector. In scaled variables,
  u = dZ / w with w_i = tol (1 + |y_i|) per component (atol = rtol = tol): the Euclidean norm
  of GMRES is the weighted norm of the stop test, whose unit is the tolerance.

No fastmath (IEEE arithmetic, no fused multiply-adds). Without numba these stay plain Python.
"""
from __future__ import annotations

import math

from gyro_sim.jit import njit

#: newton_test results
NEWTON_CONTINUE, NEWTON_CONVERGED, NEWTON_DIVERGING, NEWTON_NOT_FINITE, NEWTON_STALLED = 0, 1, 2, 3, 4
#: status of a step (both drivers): done; the state not finite after it; the rhs not finite at
#: the stages; Newton diverging; Newton not converged within its cap; the linear solve's update
#: not finite; the iteration matrix singular; the retake budget of a step spent
(STEP_OK, STEP_NONFINITE, STEP_RHS_NONFINITE, STEP_DIVERGED, STEP_NOT_CONVERGED, STEP_LINEAR,
 STEP_SINGULAR, STEP_BUDGET) = range(8)
#: the counters array (int64, 10): Newton iterations, Krylov vectors, the most Newton
#: iterations of a (sub)step, the most Krylov vectors of a solve, rhs evaluations, (sub)steps
#: accepted at the round-off floor (NEWTON_STALLED), stage-Jacobian pairs formed (dense),
#: iteration matrices factored (dense), (sub)steps retaken as two halves, the most rhs
#: evaluations of one step (all its attempts), the deepest halving of a step (a substep of
#: h / 2^depth), steps that needed a retake
(COUNT_NEWTON, COUNT_KRYLOV, COUNT_MAX_NEWTON, COUNT_MAX_KRYLOV, COUNT_RHS, COUNT_STALLED,
 COUNT_JACOBIAN, COUNT_LU, COUNT_RETAKEN, COUNT_MAX_STEP_RHS, COUNT_MAX_DEPTH,
 COUNT_STEPS_RETAKEN) = range(12)
N_COUNTS = 12
#: the parameters array (float64, 22): NEWTON_TOL, NEWTON_KAPPA, NEWTON_FIRST_TOL,
#: NEWTON_SLOW_RATE, GMRES_RTOL, GMRES_ATOL, the finite-difference eps of J v, NEWTON_CAP
#: (Krylov path), NEWTON_STALL, NEWTON_STALL_RATE, DENSE_NEWTON_CAP, JACOBIAN_REFRESH_RATE,
#: JACOBIAN_REFRESH_CAP, RETAKE_DEPTH, FLOOR_FACTOR, 1 for the dense path (0: Krylov),
#: RETAKE_BUDGET, the dense path's stop (DENSE_KAPPA; gauss4s: STRUCTURE_KAPPA),
#: DIVERGENCE_REFRESHES, the dense path's kappa in its Jacobian refresh test (DENSE_KAPPA),
#: the deepest level a step may start at (LEVEL_MAX), calm steps before a coarser one is tried
#: (LEVEL_PATIENCE)
(PAR_TOL, PAR_KAPPA, PAR_FIRST_TOL, PAR_DIVERGE, PAR_GMRES_RTOL, PAR_GMRES_ATOL, PAR_FD_EPS,
 PAR_NEWTON_CAP, PAR_STALL, PAR_STALL_RATE, PAR_DENSE_CAP, PAR_REFRESH_RATE, PAR_REFRESH_CAP,
 PAR_DEPTH, PAR_FLOOR_FACTOR, PAR_DENSE, PAR_BUDGET, PAR_DENSE_KAPPA, PAR_DIV_REFRESH,
 PAR_REFRESH_KAPPA, PAR_LEVEL_MAX, PAR_PATIENCE) = range(22)
N_PARAMS = 22
#: the memory across steps (float64, 10): the step the dense matrix was factored for (0: none),
#: the round-off floor measured with it (tolerance units), 1 when a new Jacobian is wanted
#: before the next iteration, the step of the predictor's stage increments (0: none); the
#: level the next step starts at (its pieces h / 2^level: `level_next`), the steps without a
#: retake since, the step h it refers to (0: none), the running rate of retaken steps, 1 while
#: the level is a probe (lowered, no step finished at it yet), the calm steps the next probe
#: waits for (0: the patience parameter)
DST_H, DST_FLOOR, DST_REFRESH, DST_HPRED, DST_LEVEL, DST_CALM, DST_LEVEL_H, DST_RATE, DST_PROBE, \
    DST_WAIT = range(10)
N_DSTATE = 10
#: the matrix is reused for a step within this relative difference of its own (the substeps
#: of successive calls differ in the last bits: t1 - t0 rounded)
H_REUSE = 1e-9
#: the running rate of retaken steps: r += (retaken - r) LEVEL_RATE_WEIGHT a step; above
#: LEVEL_RAISE (about 6 retaken steps in a row) the steps start a level deeper
LEVEL_RATE_WEIGHT = 0.125
LEVEL_RAISE = 0.5
#: a probe that fails doubles the wait before the next, up to LEVEL_WAIT_CAP x the patience
#: parameter; one that holds resets it
LEVEL_WAIT_CAP = 128.0
#: forward-difference Jacobians: the step of component j is JAC_REL_STEP max(1, |y_j|)
JAC_REL_STEP = 1.4901161193847656e-08  # sqrt(eps)
#: the round-off probe: each component moved by NOISE_ULPS eps (1 + |y_i|), alternating signs
NOISE_ULPS = 4.0
_EPS = 2.220446049250313e-16


@njit
def gauss_weights(y, tol, w):
    """w (n,) = tol (1 + |y|): the per-component scale of the Newton iteration."""
    for i in range(y.shape[0]):
        w[i] = tol * (1.0 + abs(y[i]))


@njit
def gauss_predict(Zp, P, Z):
    """Z (2, n) = P Zp: the starting stage increments, the previous step's collocation
    polynomial extrapolated (P from the class's `predictor`); Zp (2, n) its stage increments."""
    n = Z.shape[1]
    for s in range(2):
        for i in range(n):
            Z[s, i] = P[s, 0] * Zp[0, i] + P[s, 1] * Zp[1, i]


@njit
def gauss_stage_state(y, Z, s, Ys):
    """Ys (n,) = y + Z[s]: the state of stage s."""
    for i in range(y.shape[0]):
        Ys[i] = y[i] + Z[s, i]


@njit
def all_finite(X):
    """True when every entry of X (k, n) is finite."""
    for s in range(X.shape[0]):
        for i in range(X.shape[1]):
            if not (abs(X[s, i]) < math.inf):
                return False
    return True


@njit
def gmres_start(Z, F, hA, w, V, g):
    """The right-hand side of the Newton system, scaled, as GMRES's first basis vector.

    b = -G(Z) / w = (-Z_s + sum_j hA[s, j] F_j) / w; V[0] = b / beta, g = (beta, 0, ...).
    Returns beta = |b| (the 2-norm of the 2 n entries). beta == 0: Z solves the equations,
    V[0] is left unnormalised.
    """
    n = Z.shape[1]
    acc = 0.0
    for s in range(2):
        for i in range(n):
            b = (-Z[s, i] + (hA[s, 0] * F[0, i] + hA[s, 1] * F[1, i])) / w[i]
            V[0, s, i] = b
            acc += b * b
    beta = math.sqrt(acc)
    if beta > 0.0:
        inv = 1.0 / beta
        for s in range(2):
            for i in range(n):
                V[0, s, i] *= inv
    for j in range(g.shape[0]):
        g[j] = 0.0
    g[0] = beta
    return beta


@njit
def gmres_goal(beta, rtol, atol, n):
    """The residual (2-norm, scaled) at which GMRES stops: max(rtol beta, atol sqrt(2 n)) --
    relative (the inexact Newton forcing term) or absolute (atol in rms units of the
    tolerance: no accuracy beyond the Newton tolerance is asked)."""
    return max(rtol * beta, atol * math.sqrt(2.0 * n))


@njit
def gauss_perturbed(Ys, w, v, s, eps, out):
    """out (n,) = Ys + eps w v[s]: the state at which f is differenced for J_s (w v_s).
    Ys (n,) the stage state, v (2, n) a scaled Krylov vector."""
    for i in range(Ys.shape[0]):
        out[i] = Ys[i] + eps * (w[i] * v[s, i])


@njit
def gauss_operator(v, Fp, F, hA, w, inv_eps, out):
    """out (2, n) = v - (h A (x) I) [J_s (w v_s)] / w: the scaled Newton matrix applied to v,
    J_s (w v_s) = (Fp[s] - F[s]) / eps by forward differences (Fp[s] = f at `gauss_perturbed`)."""
    n = v.shape[1]
    for i in range(n):
        j0 = (Fp[0, i] - F[0, i]) * inv_eps
        j1 = (Fp[1, i] - F[1, i]) * inv_eps
        for s in range(2):
            out[s, i] = v[s, i] - (hA[s, 0] * j0 + hA[s, 1] * j1) / w[i]


@njit
def gmres_arnoldi(V, H, cs, sn, g, k):
    """Arnoldi step k of GMRES with its Givens rotation. On entry V[k + 1] (2, n) holds the
    operator applied to V[k]; it is orthogonalised against V[0..k] (modified Gram-Schmidt),
    normalised, column k of H (m + 1, m) filled and rotated, g (m + 1) updated. Returns the
    norm of the residual of the least-squares solution with k + 1 vectors, |g[k + 1]|.
    A breakdown (the new vector is 0: the Krylov space is invariant) leaves V[k + 1] at 0 and
    the residual exactly 0."""
    n = V.shape[2]
    for j in range(k + 1):
        acc = 0.0
        for s in range(2):
            for i in range(n):
                acc += V[j, s, i] * V[k + 1, s, i]
        H[j, k] = acc
        for s in range(2):
            for i in range(n):
                V[k + 1, s, i] -= acc * V[j, s, i]
    acc = 0.0
    for s in range(2):
        for i in range(n):
            acc += V[k + 1, s, i] * V[k + 1, s, i]
    hn = math.sqrt(acc)
    H[k + 1, k] = hn
    if hn > 0.0:
        inv = 1.0 / hn
        for s in range(2):
            for i in range(n):
                V[k + 1, s, i] *= inv
    for j in range(k):  # the previous rotations on the new column
        a, b = H[j, k], H[j + 1, k]
        H[j, k] = cs[j] * a + sn[j] * b
        H[j + 1, k] = -sn[j] * a + cs[j] * b
    a, b = H[k, k], H[k + 1, k]
    r = math.sqrt(a * a + b * b)
    if r == 0.0:
        cs[k], sn[k] = 1.0, 0.0
    else:
        cs[k], sn[k] = a / r, b / r
    H[k, k] = r
    H[k + 1, k] = 0.0
    g[k + 1] = -sn[k] * g[k]
    g[k] = cs[k] * g[k]
    return abs(g[k + 1])


@njit
def gmres_update(V, H, g, k, w, Z, coef):
    """The GMRES solution with k vectors added to Z: coef (k,) solves the triangle
    H[:k, :k] coef = g[:k]; Z += w (sum_j coef_j V[j]). Returns the rms norm of the scaled
    update sum_j coef_j V[j] (= |coef| / sqrt(2 n): V is orthonormal), the Newton step's size
    in units of the tolerance; inf or nan if the solve failed."""
    n = Z.shape[1]
    for j in range(k - 1, -1, -1):
        acc = g[j]
        for l in range(j + 1, k):
            acc -= H[j, l] * coef[l]
        coef[j] = acc / H[j, j] if H[j, j] != 0.0 else 0.0
    acc = 0.0
    for j in range(k):
        acc += coef[j] * coef[j]
    for s in range(2):
        for i in range(n):
            u = 0.0
            for j in range(k):
                u += coef[j] * V[j, s, i]
            Z[s, i] += w[i] * u
    return math.sqrt(acc / (2.0 * n))


@njit
def newton_test(norm, norm_prev, it, kappa, first_tol, diverge, stall, stall_rate):
    """The stop test of the Newton iteration after its update number `it` (0-based) of scaled
    rms size `norm` (Hairer, Wanner II, sec. IV.8, eqs. (8.10)-(8.13)): with the contraction
    rate theta = norm / norm_prev, the error left in Z is estimated by theta / (1 - theta) norm,
    converged when that is below kappa (the unit is the tolerance). The first update has no
    rate: converged when norm <= first_tol.

    The round-off floor: an update that no longer contracts (theta >= stall_rate) while it is
    already below `stall` tolerance units has reached the noise of the rhs (a component near 0
    of a large vector, e.g. a world angular-velocity component of a top spinning at 1e4 rad/s,
    carries the round-off of the |w|^2 terms): NEWTON_STALLED, accepted. Otherwise theta >=
    diverge is divergence (1 in HW).

    Returns (code, theta): NEWTON_CONVERGED, NEWTON_STALLED, NEWTON_DIVERGING,
    NEWTON_NOT_FINITE (the update is not finite) or NEWTON_CONTINUE; theta is -1 at it = 0.
    """
    if not (norm < math.inf):
        return NEWTON_NOT_FINITE, -1.0
    if it == 0 or norm_prev == 0.0:
        if norm <= first_tol:
            return NEWTON_CONVERGED, -1.0
        return NEWTON_CONTINUE, -1.0
    theta = norm / norm_prev
    if theta >= stall_rate and norm <= stall:
        return NEWTON_STALLED, theta
    if theta >= diverge:
        return NEWTON_DIVERGING, theta
    if theta / (1.0 - theta) * norm <= kappa:
        return NEWTON_CONVERGED, theta
    return NEWTON_CONTINUE, theta


@njit
def gauss_scaled(A, h, hA):
    """hA (2, 2) = h A with the symplecticity condition of the 2-stage Gauss method held exactly
    in floating point (Hairer, McLachlan, Razakarivony 2008, sec. 3): with b = (1/2, 1/2) the
    condition b_i a_ij + b_j a_ji = b_i b_j reads a_ss = 1/4 and a_01 + a_10 = 1/2. h/4 and h/2
    are exact (powers of two), h a_10 is rounded once, and h/2 - h a_10 is exact (Sterbenz:
    h a_10 ~ 0.54 h lies within a factor 2 of h/2). Rounding h a_01 on its own instead leaves
    the condition off by an ulp, and that error has a sign: it drifts the energy and the
    quadratic invariants linearly, by ~1e-17 a step (docs/integrators.md)."""
    hA[0, 0] = A[0, 0] * h
    hA[1, 1] = A[1, 1] * h
    hA[1, 0] = A[1, 0] * h
    hA[0, 1] = 0.5 * h - hA[1, 0]


@njit
def gauss_update(y, Z, F, hA, h, D):
    """y (n,) += h/2 (F[0] + F[1]) + D[0] e[0] + D[1] e[1], e_s = Z_s - sum_j hA[s, j] F_j:
    the step's result y1 = u(t + h) of the collocation polynomial, no rhs evaluation.

    F (2, n) is the rhs at the stages of the last Newton iterate, before its update; Z the
    updated stage increments. In exact arithmetic this is y + D . Z (D = b^T A^-1: h b^T F
    = D . hA F), but D = (-sqrt 3, sqrt 3) is irrational: rounded, it would scale every step's
    increment by the same 1 + 5e-17, a bias that drifts the energy and the quadratic
    invariants linearly. Here the exact h b = h/2 multiplies the increment, and the rounded D
    only the last Newton correction e (the Newton tolerance's size)."""
    hb = 0.5 * h
    for i in range(y.shape[0]):
        f0, f1 = F[0, i], F[1, i]
        e0 = Z[0, i] - (hA[0, 0] * f0 + hA[0, 1] * f1)
        e1 = Z[1, i] - (hA[1, 0] * f0 + hA[1, 1] * f1)
        y[i] += hb * (f0 + f1) + (D[0] * e0 + D[1] * e1)


# --------------------------------------------------------------------------- starting guess
@njit
def predictor_matrix(C, ratio, P):
    """P (2, 2): Z_new = P Z_old extrapolates the collocation polynomial u of the last step
    (u(t0 + x h) = y0 + sum_i L_i(x) Z_i, Lagrange basis of the nodes {0, c_1, c_2}) to the
    next step of `ratio` times its size: Z_new[s] = u(1 + ratio c_s) - u(1) (HW IV.8)."""
    for s in range(2):
        x = 1.0 + ratio * C[s]
        for i in range(2):
            ci, cj = C[i], C[1 - i]
            P[s, i] = x * (x - cj) / (ci * (ci - cj)) - (1.0 - cj) / (ci * (ci - cj))


# --------------------------------------------------------------------------- the dense path
@njit
def jac_perturb(Ys, j, Yp):
    """Yp (n,) = Ys with component j moved by d = JAC_REL_STEP max(1, |Ys_j|) (rounded so that
    Yp_j - Ys_j is exactly d); returns d. The column j of f' at Ys is (f(Yp) - f(Ys)) / d."""
    for i in range(Ys.shape[0]):
        Yp[i] = Ys[i]
    d = JAC_REL_STEP * max(1.0, abs(Ys[j]))
    Yp[j] = Ys[j] + d
    return Yp[j] - Ys[j]


@njit
def jac_column(Fp, F, d, J, j):
    """Column j of J (n, n) = (Fp - F) / d (forward difference, `jac_perturb`)."""
    inv = 1.0 / d
    for i in range(F.shape[0]):
        J[i, j] = (Fp[i] - F[i]) * inv


@njit
def newton_matrix(J, hA, M):
    """M (2n, 2n) = I - (h A (x) I) diag(J_1, J_2): block (s, q) = delta_sq I - hA[s, q] J_q;
    J (2, n, n) the stage Jacobians."""
    n = J.shape[1]
    for s in range(2):
        for q in range(2):
            a = hA[s, q]
            for i in range(n):
                row = s * n + i
                for j in range(n):
                    M[row, q * n + j] = -a * J[q, i, j]
    for i in range(2 * n):
        M[i, i] += 1.0


@njit
def lu_factor(M, piv):
    """Gaussian elimination with partial pivoting, in place: M (m, m) -> L (unit, below the
    diagonal) and U; piv (m,) int64 the row exchanged with row k at step k. Returns 0, or k + 1
    when the pivot of column k is zero or not finite (the matrix is singular to working
    precision or not finite: M is then unusable)."""
    m = M.shape[0]
    for k in range(m):
        p = k
        big = abs(M[k, k])
        for i in range(k + 1, m):
            a = abs(M[i, k])
            if a > big:
                big, p = a, i
        piv[k] = p
        if not (big > 0.0 and big < math.inf):
            return k + 1
        if p != k:
            for j in range(m):
                M[k, j], M[p, j] = M[p, j], M[k, j]
        inv = 1.0 / M[k, k]
        for i in range(k + 1, m):
            lik = M[i, k] * inv
            M[i, k] = lik
            if lik != 0.0:
                for j in range(k + 1, m):
                    M[i, j] -= lik * M[k, j]
    return 0


@njit
def lu_solve(M, piv, b):
    """b (m,) = M^-1 b in place, M and piv from `lu_factor`."""
    m = M.shape[0]
    for k in range(m):
        p = piv[k]
        if p != k:
            b[k], b[p] = b[p], b[k]
    for i in range(m):
        acc = b[i]
        for j in range(i):
            acc -= M[i, j] * b[j]
        b[i] = acc
    for i in range(m - 1, -1, -1):
        acc = b[i]
        for j in range(i + 1, m):
            acc -= M[i, j] * b[j]
        b[i] = acc / M[i, i]


@njit
def dense_residual(Z, F, hA, r):
    """r (2n,) = -G(Z) = -Z_s + sum_q hA[s, q] F_q, the stages one after the other."""
    n = Z.shape[1]
    for s in range(2):
        for i in range(n):
            r[s * n + i] = -Z[s, i] + (hA[s, 0] * F[0, i] + hA[s, 1] * F[1, i])


@njit
def dense_update(r, w, Z):
    """Z (2, n) += the update r (2n,); returns its rms size in units of the tolerance, w."""
    n = Z.shape[1]
    acc = 0.0
    for s in range(2):
        for i in range(n):
            u = r[s * n + i]
            Z[s, i] += u
            x = u / w[i]
            acc += x * x
    return math.sqrt(acc / (2.0 * n)) if n else 0.0


@njit
def scaled_rms(r, w):
    """rms of r (2n,) / w (n,) (both stages), in units of the tolerance."""
    n = w.shape[0]
    acc = 0.0
    for s in range(2):
        for i in range(n):
            x = r[s * n + i] / w[i]
            acc += x * x
    return math.sqrt(acc / (2.0 * n)) if n else 0.0


@njit
def noise_perturb(Ys, Yp):
    """Yp (n,) = Ys moved by NOISE_ULPS eps (1 + |Ys_i|) per component, signs alternating:
    a change at the level of the state's own round-off, to probe the rhs's."""
    for i in range(Ys.shape[0]):
        d = NOISE_ULPS * _EPS * (1.0 + abs(Ys[i]))
        Yp[i] = Ys[i] + d if i % 2 == 0 else Ys[i] - d


@njit
def noise_residual(Fn, F, hA, r):
    """r (2n,) = (h A (x) I) (Fn - F): the residual that round-off of the stage states makes
    (Fn (2, n) the rhs at `noise_perturb` of each stage). M^-1 r is the Newton update it
    causes: the floor below which updates are noise."""
    n = F.shape[1]
    for s in range(2):
        for i in range(n):
            r[s * n + i] = hA[s, 0] * (Fn[0, i] - F[0, i]) + hA[s, 1] * (Fn[1, i] - F[1, i])


@njit
def refresh_wanted(theta, norm, left, kappa, rate):
    """Should the stage Jacobians be formed anew at the current iterate? Yes when the
    contraction rate theta is above `rate`, or when at that rate the error estimate
    theta^left / (1 - theta) norm would still be above kappa after the `left` iterations the
    cap allows (HW IV.8, eq. (8.15): the iteration would not converge in time)."""
    if theta > rate:
        return True
    if theta <= 0.0:
        return False
    return theta ** left / (1.0 - theta) * norm > kappa


@njit
def noise_floor(noise, factor, stall):
    """The round-off floor of the dense iteration (tolerance units): `factor` times the measured
    noise of the update (`noise_residual` solved), at least `stall`; `stall` if the
    measurement is not finite."""
    if not (noise < math.inf):
        return stall
    return max(stall, factor * noise)


@njit
def retake_next(ok, pos, depth, max_depth, level):
    """The dyadic retake of a step: the step is cut into pieces of h / 2^depth on the grid of
    h / 2^max_depth (positions counted in that unit), starting at depth `level`. After a
    (sub)step of level `depth` at `pos`: on success the position moves on by its size and the
    level coarsens by one, down to `level`, when the new position lies on the coarser grid
    (back to the step's level after a hard spot); on failure the same piece is taken again as
    halves (depth + 1). Returns (pos, depth); depth > max_depth: the step fails."""
    if not ok:
        return pos, depth + 1
    pos += 1 << (max_depth - depth)
    if depth > level and pos % (1 << (max_depth - depth + 1)) == 0:
        depth -= 1
    return pos, depth


@njit
def level_start(h, dstate, max_depth):
    """The level the step of size h starts at: dstate[DST_LEVEL] when it was set for this h,
    else 0 (whole steps); at most max_depth."""
    if abs(dstate[DST_LEVEL_H] - h) > H_REUSE * h:
        for i in (DST_LEVEL, DST_CALM, DST_RATE, DST_PROBE, DST_WAIT):
            dstate[i] = 0.0
        dstate[DST_LEVEL_H] = h
    return min(int(dstate[DST_LEVEL]), max_depth)


@njit
def level_next(level, retaken, dstate, level_max, patience):
    """After a step that started at `level` and succeeded: the level of the next one.

    When most steps need a retake (the running rate above LEVEL_RAISE), the level goes one
    deeper (at most level_max): a step that fails whole is not tried whole again and again (a
    failed attempt costs Newton iterations to the cap and new Jacobians; and pieces of sizes
    chosen by the state, step after step, cost a symplectic method its bounded energy error:
    Hairer, Lubich, Wanner VIII.1). A retake now and then leaves the level alone: there whole
    steps are cheaper. After `patience` steps without a retake the level is lowered by one, a
    probe (the motion may have calmed); a retake of the probe's first step takes it back at
    once and doubles the wait for the next probe (up to LEVEL_WAIT_CAP x patience), a probe
    that holds resets it. So a steady stiff motion is taken in equal pieces, with failed
    probes ever rarer: each one's failed attempt costs a Jacobian pair for the piece size it
    tried, and the next pieces' new Jacobians move where their Newton iteration stops within
    its round-off floor (measured on the heavy top at 1e4 rad/s: a probe every 100 steps kept
    the energy's error at ~3e-10, none at 5e-13, both bounded)."""
    wait = dstate[DST_WAIT] if dstate[DST_WAIT] > 0.0 else patience
    probe = dstate[DST_PROBE] != 0.0
    if probe:  # the probe failed (doubled wait) or held (the patience again)
        wait = min(2.0 * wait, LEVEL_WAIT_CAP * patience) if retaken else patience
    dstate[DST_PROBE] = 0.0
    dstate[DST_WAIT] = wait
    rate = dstate[DST_RATE] + ((1.0 if retaken else 0.0) - dstate[DST_RATE]) * LEVEL_RATE_WEIGHT
    if (retaken and probe) or rate > LEVEL_RAISE:
        dstate[DST_LEVEL] = float(min(level + 1, level_max))
        dstate[DST_CALM] = 0.0
        dstate[DST_RATE] = 0.0
        return
    dstate[DST_RATE] = rate
    calm = 0.0 if retaken else dstate[DST_CALM] + 1.0
    if level > 0 and calm >= wait:
        dstate[DST_LEVEL] = float(level - 1)
        dstate[DST_PROBE] = 1.0
        calm = 0.0
    dstate[DST_CALM] = calm
