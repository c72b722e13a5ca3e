"""Chains of Lagrange gyroscopes (gyro_sim.analytic.lagrange): eqs (60)-(88) of the paper.

- the composed constants A^k, B^k, m^k, c^k, s^k, lambda^k (eqs 30, 31, 61-64);
- regular precessions (eq 88 and its general-n form) in an independent engine (Pinocchio,
  test/oracles/pin_chain.py) and in gyro_sim's Simulator: theta_k and psi_k' stay constant,
  and a 5 % error in the spin visibly breaks that;
- the first integrals (82) and (85), evaluated from Euler angles and rates, are conserved
  along generic motions, and equal the engines' own energy and vertical angular momentum
  through the relation documented in `lagrange.physical_invariants`;
- the shipped config/*.yaml scenes are what `lagrange.shipped_scene_dicts` regenerates.
"""
from __future__ import annotations

import copy
import sys
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
import yaml

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # test/: the oracles package

from gyro_sim.analytic import lagrange as lg
from gyro_sim.dynamics import rotations as rot
from gyro_sim.scene.load import load_scene
from oracles.pin_chain import PinChain

from gyro_sim.simulator import Simulator

REPO = Path(__file__).resolve().parents[2]
CONFIG = REPO / "config"
SIM_OPTIONS = dict(integrator="dop853", rtol=1e-11, atol=1e-12)
#: chunk and horizon of the regular-precession runs (s)
CHUNK, HORIZON = 0.05, 5.0
#: theta_k and psi_k' constant to this (rad, rad/s) in the Simulator (brief: 1e-7)
PRECESSION_TOL_SIM = 1e-7
#: ... and in the oracle (rtol = atol = 1e-12): the claim is "to round-off"
PRECESSION_TOL_ORACLE = 1e-8
#: a 5 % spin error must move theta_k or psi_k' by more than this within PERTURBED_HORIZON (s)
PERTURBED_MIN, PERTURBED_HORIZON = 1e-4, 1.0
#: first integrals (82), (85) conserved to this, relative, over 10 s
INTEGRAL_RTOL = 1e-9
#: (82), (85) through the documented relation vs the engine's own invariants, any instant
RELATION_RTOL = 1e-10


# ------------------------------------------------------------------------------- scenes
def _body(name, mass, c, axial, transverse, s=None, rotors=(), euler=None, rates=None):
    body = {"name": name, "joint": {"type": "spherical"}, "mass": mass, "com": [0.0, 0.0, c],
            "inertia": {"axial": axial, "transverse": transverse}}
    if s is not None:
        body["next_joint"] = [0.0, 0.0, s]
    if rotors:
        body["rotors"] = list(rotors)
    if euler is not None:
        body["initial"] = {"euler": list(euler), "euler_rates": list(rates)}
    return body


def _rotor(name, sign, h, mass, A, B, mode, spin):
    return {"name": name, "axis": [0.0, 0.0, sign], "position": [0.0, 0.0, h], "mass": mass,
            "axial_inertia": A, "transverse_inertia": B, "mode": mode, "spin": spin}


def _scene(name, bodies, gravity=(0.0, 0.0, -9.81), position=(0.0, 0.0, 0.0)):
    return {"name": name, "gravity": list(gravity),
            "base": {"type": "fixed", "position": list(position)}, "bodies": bodies}


def generic_chain(n: int) -> dict:
    """A Lagrange chain (torque rotor on -z, speed rotor, c^3 < 0) in a generic motion."""
    bodies = [
        _body("a", 1.1, 0.12, 0.005, 0.02, s=0.25,
              rotors=[_rotor("a_wheel", -1.0, 0.05, 0.15, 1.5e-4, 8e-5, "torque", 200.0)],
              euler=[0.3, 1.2, 0.0], rates=[2.0, -1.0, 20.0]),
        _body("b", 0.7, 0.09, 0.0015, 0.007, s=0.18 if n > 2 else None,
              rotors=[_rotor("b_motor", 1.0, 0.1, 0.1, 1e-4, 6e-5, "speed", 150.0)],
              euler=[2.0, 2.0, 0.5], rates=[-3.0, 1.5, -10.0]),
        _body("c", 0.5, -0.05, 0.001, 0.003, euler=[-1.0, 0.8, 0.0], rates=[1.0, 2.0, 30.0]),
    ][:n]
    # a base away from the origin and a tilted gravity exercise V_base and the down frame
    return _scene(f"generic Lagrange chain, n = {n}", bodies,
                  gravity=(0.5, -0.3, -9.7), position=(0.1, -0.2, 0.3))


def _precession(name, bodies, thetas, kappa, eps21=1.0):
    return lg.precession_scene_dict(name=name, bodies=bodies, thetas=thetas, kappa=kappa,
                                    eps21=eps21)


def extra_precessions() -> dict[str, dict]:
    """Regular precessions beyond the shipped ones: speed rotors, n = 3 (general-n rows)."""
    speed = [{"name": "p", "mass": 0.9, "com": [0.0, 0.0, 0.12],
              "inertia": {"axial": 0.003, "transverse": 0.016}, "next_joint": [0.0, 0.0, 0.22],
              "rotors": [_rotor("p_motor", -1.0, 0.06, 0.15, 2e-4, 1.2e-4, "speed", 250.0)]},
             {"name": "q", "mass": 0.6, "com": [0.0, 0.0, 0.07],
              "inertia": {"axial": 0.0015, "transverse": 0.005},
              "rotors": [_rotor("q_wheel", 1.0, 0.07, 0.1, 1e-4, 6e-5, "torque", 120.0)]}]
    three = [{"name": "u1", "mass": 1.0, "com": [0.0, 0.0, 0.1],
              "inertia": {"axial": 0.004, "transverse": 0.015}, "next_joint": [0.0, 0.0, 0.2]},
             {"name": "u2", "mass": 0.8, "com": [0.0, 0.0, 0.08],
              "inertia": {"axial": 0.002, "transverse": 0.008}, "next_joint": [0.0, 0.0, 0.15]},
             {"name": "u3", "mass": 0.5, "com": [0.0, 0.0, 0.06],
              "inertia": {"axial": 0.001, "transverse": 0.003}}]
    return {
        "speed_rotor": _precession("double gyroscope with a speed rotor", speed, [0.7, 1.1],
                                   -5.0, -1.0),
        "three_plus_minus": _precession("three gyroscopes", three, [0.5, 0.8, 1.0], -7.0,
                                        [1.0, -1.0]),
        "three_minus_plus": _precession("three gyroscopes", three, [0.5, 0.8, 1.0], -7.0,
                                        [-1.0, 1.0]),
    }


PRECESSIONS = {**lg.shipped_scene_dicts(), **extra_precessions()}
#: the shipped cases run by default, the others are marked slow
PRECESSION_CASES = [
    pytest.param(case, marks=() if case in lg.SHIPPED_SCENES else pytest.mark.slow)
    for case in PRECESSIONS]
GENERIC_N = [2, pytest.param(3, marks=pytest.mark.slow)]


def _perturbed(scene: dict, factor: float = 1.05) -> dict:
    """The same scene with every phi_k' multiplied by `factor`."""
    scene = copy.deepcopy(scene)
    for body in scene["bodies"]:
        body["initial"]["euler_rates"][2] *= factor
    return scene


def _nu(scene) -> np.ndarray:
    return np.asarray(scene.gravity, dtype=float) / np.linalg.norm(scene.gravity)


# ----------------------------------------------------------------------- the engines
def oracle_euler(scene, t_eval) -> tuple[PinChain, list, np.ndarray, np.ndarray]:
    """Pinocchio run: states, Euler angles (T, n, 3) and rates (T, n, 3) at t_eval."""
    pc = PinChain(scene)
    states = pc.run(float(t_eval[-1]), t_eval=t_eval)
    down = rot.down_frame(_nu(scene))
    E, R = [], []
    for st in states:
        bodies = pc.bodies(st)
        e = [rot.matrix_to_euler(b.rotation, down) for b in bodies]
        E.append(e)
        R.append([rot.omega_to_euler_rates(ek, b.angular_velocity, down)
                  for ek, b in zip(e, bodies)])
    return pc, states, np.array(E), np.array(R)


def oracle_invariants(pc: PinChain, state) -> dict[str, float]:
    """Pinocchio's own T + V and the upward vertical angular momentum about O^1."""
    scene = pc.scene
    hg = pin.computeCentroidalMomentum(pc.model, pc.data, state.q, state.v)  # about the com
    com = pin.centerOfMass(pc.model, pc.data, state.q)
    L = hg.angular + np.cross(com - scene.base.position, hg.linear)  # about O^1
    return {"energy": pc.energy(state), "vertical_momentum": float(-_nu(scene) @ L)}


def sim_euler(sim, names) -> tuple[np.ndarray, np.ndarray]:
    """Euler angles and rates (n, 3) of the bodies `names` from sim.joint_states()."""
    js = sim.joint_states()
    index = {name: i for i, name in enumerate(js.name)}
    E = np.array([[js.position[index[f"{b}_{a}"]] for a in ("psi", "theta", "phi")]
                  for b in names])
    R = np.array([[js.velocity[index[f"{b}_{a}"]] for a in ("psi", "theta", "phi")]
                  for b in names])
    return E, R


def sim_run(scene_dict, horizon: float) -> tuple[object, np.ndarray, np.ndarray]:
    """Simulator in CHUNK steps to `horizon`: Euler angles/rates (T, n, 3) incl. t = 0."""
    sim = Simulator(load_scene(scene_dict), **SIM_OPTIONS)
    names = [b["name"] for b in scene_dict["bodies"]]
    E, R = [], []
    for i in range(int(round(horizon / CHUNK)) + 1):
        if i:
            sim.advance(CHUNK)
        e, r = sim_euler(sim, names)
        E.append(e)
        R.append(r)
    return sim, np.array(E), np.array(R)


def precession_deviation(E: np.ndarray, R: np.ndarray, kappa: float) -> float:
    """max over time and bodies of |theta_k - theta_k(0)| and |psi_k' - kappa|."""
    return float(max(np.max(np.abs(E[:, :, 1] - E[0, :, 1])), np.max(np.abs(R[:, :, 0] - kappa))))


def _kappa(scene_dict) -> float:
    return scene_dict["bodies"][0]["initial"]["euler_rates"][0]


# ---------------------------------------------------------------- composed constants
def test_compose_constants():
    scene = load_scene(_scene("composition", [
        _body("a", 1.0, 0.1, 0.004, 0.015, s=0.2, rotors=[
            _rotor("t", -1.0, 0.05, 0.2, 2e-4, 1e-4, "torque", 300.0),
            _rotor("v", 1.0, 0.15, 0.1, 3e-4, 2e-4, "speed", 40.0)]),
        _body("b", 0.5, -0.02, 0.001, 0.003)], position=(0.0, 0.0, 1.0)))
    ch = lg.LagrangeChain.from_scene(scene)
    assert ch is not None and ch.names == ("a", "b")
    m1 = 1.0 + 0.2 + 0.1
    np.testing.assert_allclose(ch.m, [m1, 0.5])
    np.testing.assert_allclose(ch.c, [(0.1 + 0.2 * 0.05 + 0.1 * 0.15) / m1, -0.02])
    np.testing.assert_allclose(ch.s, [0.2, 0.0])
    # axial: carrier + speed rotors only; transverse: every rotor's B_i + m_i h_i^2
    np.testing.assert_allclose(ch.A, [0.004 + 3e-4, 0.001])
    np.testing.assert_allclose(ch.B, [0.015 + 1e-4 + 0.2 * 0.05**2 + 2e-4 + 0.1 * 0.15**2,
                                      0.003])
    # lambda: torque rotor -A_i p_i (axis -z), speed rotor +A_i kappa_i'
    np.testing.assert_allclose(ch.lam, [-2e-4 * 300.0 + 3e-4 * 40.0, 0.0])
    np.testing.assert_allclose(ch.lam_speed, [3e-4 * 40.0, 0.0])
    np.testing.assert_allclose(ch.rotor_energy, [0.5 * (2e-4 * 300.0**2 + 3e-4 * 40.0**2), 0])
    np.testing.assert_allclose(ch.mu, [(m1 * ch.c[0] + 0.2 * 0.5) * 9.81 / ch.B[0],
                                       0.5 * -0.02 * 9.81 / 0.003])  # (72)
    np.testing.assert_allclose(ch.nu, [0.0, 0.0, -1.0])
    np.testing.assert_allclose(ch.base, [0.0, 0.0, 1.0])


def _not_lagrange(change):
    d = _scene("x", [_body("a", 1.0, 0.1, 0.004, 0.015, s=0.2,
                           rotors=[_rotor("r", 1.0, 0.05, 0.2, 2e-4, 1e-4, "torque", 3.0)]),
                     _body("b", 0.5, 0.05, 0.001, 0.003)])
    change(d)
    return d


NOT_LAGRANGE = {
    "hinge": lambda d: d["bodies"][1].update(joint={"type": "hinge", "axis": [1.0, 0.0, 0.0]}),
    "no gravity": lambda d: d.pop("gravity"),
    "free base": lambda d: d.update(base={"type": "free", "position": [0.0, 0.0, 0.0]}),
    "moving base": lambda d: d.update(base={"type": "moving", "position": [0.0, 0.0, 0.0],
                                            "motion": {"type": "sine",
                                                       "amplitude": [0.0, 0.0, 0.01],
                                                       "frequency": 5.0}}),
    "com off axis": lambda d: d["bodies"][1].update(com=[0.01, 0.0, 0.05]),
    "joint off axis": lambda d: d["bodies"][0].update(next_joint=[0.0, 0.01, 0.2]),
    "asymmetric inertia": lambda d: d["bodies"][1].update(
        inertia=None, inertia_com=[[0.0018, 0.0, 0.0], [0.0, 0.0016, 0.0], [0.0, 0.0, 0.001]]),
    "rotor axis tilted": lambda d: d["bodies"][0]["rotors"][0].update(axis=[0.0, 0.6, 0.8]),
    "rotor off axis": lambda d: d["bodies"][0]["rotors"][0].update(position=[0.02, 0.0, 0.05]),
}


@pytest.mark.parametrize("case", list(NOT_LAGRANGE))
def test_from_scene_rejects(case):
    assert lg.LagrangeChain.from_scene(load_scene(_not_lagrange(NOT_LAGRANGE[case]))) is None


def test_from_scene_accepts_inertia_com_form():
    """The same gyrostat written with inertia_com (about the centre of mass) is accepted."""
    d = _not_lagrange(lambda d: d["bodies"][1].update(
        inertia=None, inertia_com=[[0.003 - 0.5 * 0.05**2, 0.0, 0.0],
                                   [0.0, 0.003 - 0.5 * 0.05**2, 0.0], [0.0, 0.0, 0.001]]))
    ch = lg.LagrangeChain.from_scene(load_scene(d))
    np.testing.assert_allclose(ch.B[1], 0.003, rtol=1e-14)


# ------------------------------------------------------------- regular precession formulas
def test_spins_heavy_top_classical():
    """n = 1: A phi' = (B - A) kappa cos th - m c g / kappa - lambda."""
    d = _scene("top", [_body("t", 1.0, 0.1, 0.004, 0.015, rotors=[
        _rotor("w", 1.0, 0.05, 0.2, 2e-4, 1e-4, "torque", 100.0)])])
    ch = lg.LagrangeChain.from_scene(load_scene(d))
    th, kappa = 2.5, 4.0  # an upright top this time
    A, B, m, c, lam = ch.A[0], ch.B[0], ch.m[0], ch.c[0], ch.lam[0]
    expected = ((B - A) * kappa * np.cos(th) - m * c * 9.81 / kappa - lam) / A
    np.testing.assert_allclose(lg.regular_precession_spins(ch, [th], kappa), [expected],
                               rtol=1e-14)


@pytest.mark.parametrize("eps21", [1.0, -1.0])
def test_spins_double_gyroscope_eq88(eps21):
    """The general-n rows reduce to docs/theory.md's (88) for n = 2."""
    ch = lg.LagrangeChain.from_scene(load_scene(PRECESSIONS["double_gyro_plus.yaml"]))
    th1, th2, kappa, g = 0.6, 0.9, -6.0, 9.81
    A1, A2, B1, B2 = *ch.A, *ch.B
    m1, m2, c1, c2, s1 = *ch.m, *ch.c, ch.s[0]
    l1, l2 = ch.lam
    phi1 = ((B1 - A1 + m2 * s1 * s1 + eps21 * np.sin(th2) / np.sin(th1) * m2 * c2 * s1)
            * kappa * np.cos(th1) - (m1 * c1 + m2 * s1) * g / kappa - l1) / A1
    phi2 = ((B2 - A2 + eps21 * np.sin(th1) / np.sin(th2) * m2 * c2 * s1) * kappa * np.cos(th2)
            - m2 * c2 * g / kappa - l2) / A2
    np.testing.assert_allclose(lg.regular_precession_spins(ch, [th1, th2], kappa, eps21),
                               [phi1, phi2], rtol=1e-13)


def test_precession_state_layout():
    ch = lg.LagrangeChain.from_scene(load_scene(PRECESSIONS["three_plus_minus"]))
    euler, rates = lg.regular_precession_state(ch, [0.5, 0.8, 1.0], -7.0, [1.0, -1.0], psi1=0.3)
    np.testing.assert_allclose(euler[:, 0], [0.3, 0.3, 0.3 + np.pi])
    np.testing.assert_allclose(rates[:, :2], [[-7.0, 0.0]] * 3)
    with pytest.raises(ValueError):
        lg.regular_precession_spins(ch, [0.5, 0.8, 1.0], -7.0, 1.0)  # n = 3 needs 2 signs
    with pytest.raises(ValueError):
        lg.regular_precession_spins(ch, [0.5, 0.0, 1.0], -7.0, [1.0, 1.0])  # vertical axis


# ------------------------------------------------------------ regular precession, engines
@pytest.mark.parametrize("case", PRECESSION_CASES)
@pytest.mark.slow
def test_regular_precession_independent_engine(case):
    """Pinocchio (DOP853, rtol = atol = 1e-12) keeps theta_k and psi_k' to round-off."""
    scene_dict = PRECESSIONS[case]
    t = np.linspace(0.0, HORIZON, int(round(HORIZON / CHUNK)) + 1)
    _, _, E, R = oracle_euler(load_scene(scene_dict), t)
    dev = precession_deviation(E, R, _kappa(scene_dict))
    print(f"{case}: oracle max |theta - theta0|, |psi' - kappa| over {HORIZON} s = {dev:.2e}")
    assert dev < PRECESSION_TOL_ORACLE


@pytest.mark.parametrize("case", ["double_gyro_plus.yaml", "three_plus_minus"])
@pytest.mark.slow
def test_regular_precession_independent_engine_perturbed(case):
    """A 5 % error in phi_k' breaks the precession: the checks above can fail."""
    scene_dict = _perturbed(PRECESSIONS[case])
    t = np.linspace(0.0, PERTURBED_HORIZON, int(round(PERTURBED_HORIZON / CHUNK)) + 1)
    _, _, E, R = oracle_euler(load_scene(scene_dict), t)
    assert precession_deviation(E, R, _kappa(scene_dict)) > PERTURBED_MIN


@pytest.mark.slow
def test_general_n_printed_sign_fails():
    """The transcription's eps_ql (for eps_kl) in the inner sum of the general-n rows gives a
    different phi_2' for n = 3, eps = (+1, -1), and that state does not precess regularly."""
    scene_dict = copy.deepcopy(PRECESSIONS["three_plus_minus"])
    chain = lg.LagrangeChain.from_scene(load_scene(scene_dict))
    th, kappa = np.array([0.5, 0.8, 1.0]), -7.0
    sigma = np.array([1.0, 1.0, -1.0])  # psi_3 = psi_2 + pi
    eps = np.outer(sigma, sigma)
    m, c, s, sn, k = chain.m, chain.c, chain.s, np.sin(th), 1
    S = m[k] * c[k] * eps[k, 0] * s[0] * sn[0] + s[k] * m[2] * (
        eps[k, 2] * c[2] * sn[2] + sum(eps[2, l] * s[l] * sn[l] for l in range(2)))  # eps_ql
    Bn = chain.B[k] * (kappa * np.cos(th[k]) - chain.mu[k] / kappa) \
        + kappa * np.cos(th[k]) * S / sn[k]
    printed = (Bn - chain.lam[k]) / chain.A[k] - kappa * np.cos(th[k])
    corrected = lg.regular_precession_spins(chain, th, kappa, [1.0, -1.0])[k]
    assert abs(printed - corrected) > 1.0
    scene_dict["bodies"][k]["initial"]["euler_rates"][2] = float(printed)
    t = np.linspace(0.0, PERTURBED_HORIZON, int(round(PERTURBED_HORIZON / CHUNK)) + 1)
    _, _, E, R = oracle_euler(load_scene(scene_dict), t)
    assert precession_deviation(E, R, kappa) > PERTURBED_MIN


@pytest.mark.parametrize("case", PRECESSION_CASES)
def test_regular_precession_simulator(case):
    scene_dict = PRECESSIONS[case]
    _, E, R = sim_run(scene_dict, HORIZON)
    dev = precession_deviation(E, R, _kappa(scene_dict))
    print(f"{case}: Simulator max |theta - theta0|, |psi' - kappa| over {HORIZON} s = {dev:.2e}")
    assert dev < PRECESSION_TOL_SIM


@pytest.mark.parametrize("case", ["heavy_top.yaml", "double_gyro_plus.yaml",
                                  "double_gyro_minus.yaml"])
def test_regular_precession_simulator_perturbed(case):
    scene_dict = _perturbed(PRECESSIONS[case])
    _, E, R = sim_run(scene_dict, PERTURBED_HORIZON)
    dev = precession_deviation(E, R, _kappa(scene_dict))
    print(f"{case}, phi' * 1.05: deviation {dev:.2e}")
    assert dev > PERTURBED_MIN


# ----------------------------------------------------------------- first integrals
def _85_variant(chain, euler, rates, mu_factor, off_diagonal_only):
    """(85) with the transcription's errors put back, one at a time or both.

    mu_factor = 1: the printed -mu_k cos th_k (correct: 2); off_diagonal_only: the printed
    double sum over l < q only (correct: over all l, q < k).
    """
    psi, th = euler[:, 0], euler[:, 1]
    dpsi, dth = rates[:, 0], rates[:, 1]
    sn, cs = np.sin(th), np.cos(th)

    def G(l, q):
        return (dth[l] * dth[q] * sn[l] * sn[q]
                + (dth[l] * dth[q] * cs[l] * cs[q] + dpsi[l] * dpsi[q] * sn[l] * sn[q])
                * np.cos(psi[l] - psi[q])
                + (dth[l] * dpsi[q] * cs[l] * sn[q] - dth[q] * dpsi[l] * cs[q] * sn[l])
                * np.sin(psi[l] - psi[q]))

    m, c, s = chain.m, chain.c, chain.s
    h = float(np.sum((dth**2 + dpsi**2 * sn**2 - mu_factor * chain.mu * cs) * chain.B))
    for k in range(1, chain.n):
        pairs = ([(l, q) for l in range(k) for q in range(l + 1, k)] if off_diagonal_only
                 else [(l, q) for l in range(k) for q in range(k)])
        h += m[k] * (2 * c[k] * sum(s[l] * G(l, k) for l in range(k))
                     + sum(s[l] * s[q] * G(l, q) for l, q in pairs))
    return h


def _drift(values) -> float:
    values = np.asarray(values)
    return float(np.max(np.abs(values - values[0])) / abs(values[0]))


def _check_integrals(chain, E, R, reference, label):
    """(82), (85) conserved; equal to the engine's invariants through the relation."""
    drift_h = _drift([lg.energy_integral_85(chain, e, r) for e, r in zip(E, R)])
    drift_k = _drift([lg.vertical_momentum_82(chain, e, r) for e, r in zip(E, R)])
    phys = [lg.physical_invariants(chain, e, r) for e, r in zip(E, R)]
    err = {key: max(abs(p[key] - q[key]) / abs(q[key]) for p, q in zip(phys, reference))
           for key in ("energy", "vertical_momentum")}
    # the transcription's (85): each of its two errors alone destroys the integral
    drift_mu = _drift([_85_variant(chain, e, r, 1.0, False) for e, r in zip(E, R)])
    drift_sum = _drift([_85_variant(chain, e, r, 2.0, True) for e, r in zip(E, R)])
    print(f"{label}: drift (85) {drift_h:.1e}, (82) {drift_k:.1e}; vs engine: energy "
          f"{err['energy']:.1e}, vertical momentum {err['vertical_momentum']:.1e}; "
          f"printed -mu cos th drifts {drift_mu:.1e}, printed double sum drifts {drift_sum:.1e}")
    assert drift_h < INTEGRAL_RTOL and drift_k < INTEGRAL_RTOL
    assert err["energy"] < RELATION_RTOL and err["vertical_momentum"] < RELATION_RTOL
    assert drift_mu > 1e-3 and drift_sum > 1e-3


@pytest.mark.parametrize("n", GENERIC_N)
@pytest.mark.slow
def test_integrals_independent_engine(n):
    scene = load_scene(generic_chain(n))
    chain = lg.LagrangeChain.from_scene(scene)
    t = np.linspace(0.0, 10.0, 201)
    pc, states, E, R = oracle_euler(scene, t)
    _check_integrals(chain, E, R, [oracle_invariants(pc, st) for st in states],
                     f"oracle n = {n}")


@pytest.mark.parametrize("n", GENERIC_N)
def test_integrals_simulator(n):
    scene_dict = generic_chain(n)
    chain = lg.LagrangeChain.from_scene(load_scene(scene_dict))
    sim = Simulator(load_scene(scene_dict), **SIM_OPTIONS)
    names = [b["name"] for b in scene_dict["bodies"]]
    E, R, ref = [], [], []
    for i in range(201):
        if i:
            sim.advance(CHUNK)
        e, r = sim_euler(sim, names)
        E.append(e)
        R.append(r)
        ref.append(sim.invariants())
    _check_integrals(chain, np.array(E), np.array(R), ref, f"Simulator n = {n}")


def test_integrals_relation_at_random_states():
    """At arbitrary states (no integration): (82), (85) vs Pinocchio's T + V and K."""
    rng = np.random.default_rng(7)
    for n in (1, 2, 3):
        scene_dict = generic_chain(max(n, 2))
        scene_dict["bodies"] = scene_dict["bodies"][:n]
        scene_dict["bodies"][-1].pop("next_joint", None)
        for _ in range(5):
            for body in scene_dict["bodies"]:
                body["initial"] = {"euler": [float(rng.uniform(-3, 3)), float(rng.uniform(0.2, 3)),
                                             float(rng.uniform(-3, 3))],
                                   "euler_rates": rng.uniform(-5, 5, size=3).tolist()}
            scene = load_scene(scene_dict)
            chain = lg.LagrangeChain.from_scene(scene)
            pc = PinChain(scene)
            st = pc.initial_state()
            E = np.array([b["initial"]["euler"] for b in scene_dict["bodies"]])
            R = np.array([b["initial"]["euler_rates"] for b in scene_dict["bodies"]])
            got = lg.physical_invariants(chain, E, R)
            ref = oracle_invariants(pc, st)
            for key in ("energy", "vertical_momentum"):
                assert abs(got[key] - ref[key]) <= RELATION_RTOL * abs(ref[key]), (n, key)


# -------------------------------------------------------------------- shipped scenes
@pytest.mark.parametrize("fname", list(lg.SHIPPED_SCENES))
def test_config_yaml_regenerates(fname):
    path = CONFIG / fname
    text = path.read_text(encoding="utf-8")
    expected = lg.shipped_scene_dicts()[fname]
    assert yaml.safe_load(text) == expected, (
        f"{path} is stale: regenerate with `python -m gyro_sim.analytic.lagrange config`")
    assert text == lg.scene_yaml(expected, lg._header(fname, lg.SHIPPED_SCENES[fname]))
    # through the loader, from_scene sees the chain the file was generated from
    scene = load_scene(str(path))
    chain = lg.LagrangeChain.from_scene(scene)
    args = lg.SHIPPED_SCENES[fname]
    spins = lg.regular_precession_spins(chain, args["thetas"], args["kappa"],
                                        args.get("eps21", 1.0))
    np.testing.assert_array_equal(spins, [b.initial.euler_rates[2] for b in scene.bodies])
