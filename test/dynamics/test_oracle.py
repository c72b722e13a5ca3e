"""gyro_sim against an independent engine: the same chains built in Pinocchio (test/oracles).

First the oracle is checked on its own (a pendulum's period, a hanging chain's reactions,
energy conservation, the regular precessions of eq (88)); then random chains -- mixed
spherical joints and hinges with random axes, random masses and inertias, torque and speed
rotors, gravity, a constant command on every actuated axis, fixed / free / moving base -- are
run in both engines and compared body by body at t = 1 s, and the joint wrenches (eqs 40,
48) are compared at t = 0 and t = 1 s.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # test/: the oracles package

from gyro_sim.dynamics import rotations as rot
from gyro_sim.scene.records import Base, Body, Initial, Joint, Rotor, Scene
from oracles.pin_chain import PinChain

from gyro_sim import Simulator, load_scene

G = 9.81
T_FINAL = 1.0
#: states at t = 1 s (positions in m, rotations, rates in rad/s and m/s are all O(1))
STATE_ATOL = 1e-6
#: wrenches from the same state: both sides are algebra on that state
WRENCH_RTOL = 1e-8
#: wrenches at t = 1 s, each side on its own trajectory
WRENCH_TRAJ_RTOL = 1e-6
#: relative energy drift of the oracle over 1 s at rtol = atol = 1e-12
ENERGY_RTOL = 1e-10
SIM_OPTIONS = dict(integrator="dop853", rtol=1e-11, atol=1e-12)



# ------------------------------------------------------------------ scenes
def _unit(v) -> np.ndarray:
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v)


def _random_rotation(rng: np.random.Generator) -> np.ndarray:
    return rot.quat_to_matrix(_unit(rng.normal(size=4)))


def _random_inertia_com(rng: np.random.Generator, mass: float) -> np.ndarray:
    """A physical inertia about the centre of mass: I = tr(P) 1 - P with P = R diag(p) R^T,
    p > 0 the second moments, so the principal moments obey the triangle inequality."""
    p = mass * rng.uniform(0.002, 0.02, size=3)
    R = _random_rotation(rng)
    P = R @ np.diag(p) @ R.T
    return np.trace(P) * np.eye(3) - P


def _inertia_at_O(mass: float, com, inertia_com) -> np.ndarray:
    c = np.asarray(com, dtype=float)
    return np.asarray(inertia_com, dtype=float) + mass * ((c @ c) * np.eye(3) - np.outer(c, c))


def random_chain(seed: int, base: str = "fixed", conservative: bool = False) -> dict:
    """A random scene in the scene-file form (docs/scene-format.md).

    conservative: no speed rotors (the base is then never `moving`), so that T + V is a
    first integral when no axis moment is applied.
    """
    rng = np.random.default_rng(seed)
    n = int(rng.integers(2, 6))
    # gravity mostly down, sometimes tilted (exercises the Euler angles' down frame)
    g = np.array([0.0, 0.0, -G])
    if rng.random() < 0.3:
        g = G * _unit(np.array([0.0, 0.0, -1.0]) + 0.4 * rng.normal(size=3))
    scene: dict = {"name": f"random chain {seed} ({base})", "gravity": g.tolist()}
    position = rng.uniform(-0.5, 0.5, size=3)
    if base == "fixed":
        scene["base"] = {"type": "fixed", "position": position.tolist()}
    elif base == "moving":
        scene["base"] = {"type": "moving", "position": position.tolist(),
                         "motion": {"type": "sine",
                                    "amplitude": rng.uniform(-0.02, 0.02, size=3).tolist(),
                                    "frequency": float(rng.uniform(1.0, 4.0))}}
    else:
        scene["base"] = {"type": "free", "position": position.tolist(),
                         "velocity": rng.uniform(-0.3, 0.3, size=3).tolist()}
    bodies = []
    for k in range(n):
        name = f"b{k + 1}"
        hinge = rng.random() < 0.5 and not (k == 0 and base == "free")
        mass = float(rng.uniform(0.5, 2.0))
        body: dict = {
            "name": name,
            "joint": ({"type": "hinge", "axis": _unit(rng.normal(size=3)).tolist()} if hinge
                      else {"type": "spherical"}),
            "mass": mass,
            "com": (rng.uniform(-0.05, 0.05, size=3) + [0.0, 0.0, 0.15]).tolist(),
            "inertia_com": _random_inertia_com(rng, mass).tolist(),
        }
        if k < n - 1:
            body["next_joint"] = (rng.uniform(-0.1, 0.1, size=3) + [0.0, 0.0, 0.35]).tolist()
        rotors = []
        for i in range(int(rng.integers(0, 3))):
            A = float(rng.uniform(1e-4, 5e-4))
            speed = rng.random() < 0.35 and not conservative
            rotors.append({
                "name": f"{name}_r{i + 1}",
                "axis": _unit(rng.normal(size=3)).tolist(),
                "position": rng.uniform(-0.1, 0.1, size=3).tolist(),
                "mass": float(rng.uniform(0.05, 0.2)),
                "axial_inertia": A,
                "transverse_inertia": float(A * rng.uniform(0.55, 1.2)),
                "mode": "speed" if speed else "torque",
                "spin": float(rng.uniform(-30.0, 30.0)),
                "actuated": bool(not speed and rng.random() < 0.6),
            })
        if rotors:
            body["rotors"] = rotors
        if hinge:
            body["initial"] = {"angle": float(rng.uniform(-1.0, 1.0)),
                               "rate": float(rng.uniform(-2.0, 2.0))}
        elif rng.random() < 0.5:
            body["initial"] = {"euler": [float(rng.uniform(-np.pi, np.pi)),
                                         float(rng.uniform(0.3, 2.8)),
                                         float(rng.uniform(-np.pi, np.pi))],
                               "euler_rates": rng.uniform(-2.0, 2.0, size=3).tolist()}
        else:
            body["initial"] = {"quaternion": _unit(rng.normal(size=4)).tolist(),
                               "angular_velocity": rng.uniform(-2.0, 2.0, size=3).tolist()}
        bodies.append(body)
    scene["bodies"] = bodies
    return scene


def records(d: dict) -> Scene:
    """The Scene records of a scene dict written by this file (the oracle's own reading,
    independent of gyro_sim's loader; only the keys used here)."""
    g = d.get("gravity")
    b = d["base"]
    motion = b.get("motion", {})
    base = Base(b["type"], np.array(b.get("position", [0.0, 0.0, 0.0]), dtype=float),
                np.array(motion["amplitude"], dtype=float) if motion else None,
                float(motion["frequency"]) if motion else None,
                np.array(b["velocity"], dtype=float) if "velocity" in b else None)
    bodies = []
    for bd in d["bodies"]:
        j = bd["joint"]
        joint = Joint(j["type"], _unit(j["axis"]) if "axis" in j else None)
        mass = float(bd["mass"])
        com = np.array(bd["com"], dtype=float)
        if "inertia_com" in bd:
            inertia = _inertia_at_O(mass, com, bd["inertia_com"])
        else:
            inertia = np.diag([bd["inertia"]["transverse"]] * 2 + [bd["inertia"]["axial"]])
        rotors = tuple(
            Rotor(r["name"], _unit(r["axis"]), np.array(r["position"], dtype=float),
                  float(r["mass"]), float(r["axial_inertia"]), float(r["transverse_inertia"]),
                  r["mode"], float(r["spin"]), bool(r.get("actuated", False)))
            for r in bd.get("rotors", ()))
        ini = bd.get("initial", {})

        def arr(key, ini=ini):
            return np.array(ini[key], dtype=float) if key in ini else None

        if joint.type == "hinge":
            initial = Initial(angle=float(ini.get("angle", 0.0)), rate=float(ini.get("rate", 0.0)))
        elif "quaternion" in ini:
            initial = Initial(quaternion=_unit(ini["quaternion"]),
                              angular_velocity=arr("angular_velocity"))
        else:
            initial = Initial(euler=arr("euler") if "euler" in ini else np.zeros(3),
                              euler_rates=arr("euler_rates") if "euler_rates" in ini
                              else np.zeros(3))
        nxt = bd.get("next_joint")
        bodies.append(Body(bd["name"], joint, mass, com, inertia,
                           None if nxt is None else np.array(nxt, dtype=float), rotors, initial))
    return Scene(d["name"], None if g is None else np.array(g, dtype=float), base, tuple(bodies),
                 source=d)


def axis_moments_for(chain: PinChain, seed: int) -> np.ndarray:
    rng = np.random.default_rng(1000 + seed)
    return rng.uniform(-0.5, 0.5, size=len(chain.axis_names))


# ------------------------------------------------------- the oracle alone
def _pendulum(joint: dict, initial: dict) -> dict:
    return {"name": "compound pendulum", "gravity": [0.0, 0.0, -G],
            "base": {"type": "fixed", "position": [0.0, 0.0, 1.0]},
            "bodies": [{"name": "p", "joint": joint, "mass": 2.0, "com": [0.0, 0.0, 0.5],
                        "inertia": {"axial": 0.01, "transverse": 0.6}, "initial": initial}]}


@pytest.mark.parametrize("form", ["hinge", "spherical"])
def test_oracle_pendulum_period(form):
    """Small oscillations of a compound pendulum: period 2 pi sqrt(B / (m g c))."""
    theta0 = 1e-4
    if form == "hinge":  # body z-axis hangs down at angle 0 (Rx(pi)) only for the spherical
        d = _pendulum({"type": "hinge", "axis": [1.0, 0.0, 0.0]},
                      {"angle": np.pi + theta0, "rate": 0.0})
    else:
        d = _pendulum({"type": "spherical"}, {"euler": [0.3, theta0, 0.0],
                                              "euler_rates": [0.0, 0.0, 0.0]})
    chain = PinChain(records(d))
    B, m, c = 0.6, 2.0, 0.5
    period = 2.0 * np.pi * np.sqrt(B / (m * G * c))
    omega0 = 2.0 * np.pi / period
    states = chain.run(period, t_eval=[0.25 * period, 0.5 * period, period])
    down = rot.down_frame(np.array([0.0, 0.0, -1.0]))
    thetas = [np.arccos(np.clip(chain.bodies(s)[0].rotation[:, 2] @ down[:, 2], -1, 1))
              for s in states]
    # a quarter period: hanging (theta ~ 0, fastest); half: theta0 on the other side; full: back
    assert thetas[0] < 1e-3 * theta0
    # the amplitude correction of the period is theta0^2 / 16 relative: negligible here
    assert thetas[1] == pytest.approx(theta0, rel=1e-6)
    assert thetas[2] == pytest.approx(theta0, rel=1e-6)
    w_quarter = np.linalg.norm(chain.bodies(states[0])[0].angular_velocity)
    assert w_quarter == pytest.approx(theta0 * omega0, rel=1e-6)
    assert np.linalg.norm(chain.bodies(states[2])[0].angular_velocity) < 1e-6 * theta0 * omega0


def test_oracle_hanging_chain_reactions():
    """A chain hanging at rest: R^k is the weight of bodies k..n (with their rotors), L^k = 0,
    in body k's frame; rotors spinning about the vertical change nothing."""
    d = {"name": "hanging", "gravity": [0.0, 0.0, -G],
         "base": {"type": "fixed", "position": [0.0, 0.0, 0.0]}, "bodies": []}
    masses = [1.0, 0.7, 0.4]
    for k, m in enumerate(masses):
        body = {"name": f"b{k}", "joint": {"type": "spherical"}, "mass": m,
                "com": [0.0, 0.0, 0.2], "inertia": {"axial": 0.01, "transverse": 0.05},
                "initial": {"euler": [0.7 * k, 0.0, 0.0], "euler_rates": [0.0, 0.0, 0.0]},
                "rotors": [{"name": f"r{k}", "axis": [0.0, 0.0, 1.0],
                            "position": [0.0, 0.0, 0.1], "mass": 0.1, "axial_inertia": 2e-4,
                            "transverse_inertia": 1.5e-4, "mode": "torque", "spin": 50.0}]}
        if k < len(masses) - 1:
            body["next_joint"] = [0.0, 0.0, 0.4]
        d["bodies"].append(body)
    chain = PinChain(records(d))
    state = chain.initial_state()
    a = chain.accelerations(state)
    assert np.abs(a).max() < 1e-12
    for k, w in enumerate(chain.reactions(state)):
        weight = G * sum(m + 0.1 for m in masses[k:])
        # hanging: body z = world -z, so the upward support is along body -z
        np.testing.assert_allclose(w.force, [0.0, 0.0, -weight], atol=1e-12)
        np.testing.assert_allclose(w.moment, 0.0, atol=1e-12)


CONSERVATIVE = [(seed, base) for seed in range(4) for base in ("fixed", "free")]


@pytest.mark.parametrize("seed,base", CONSERVATIVE)
@pytest.mark.slow
def test_oracle_energy_conserved(seed, base):
    """T + V (pinocchio's own energy functions) over 1 s of a random conservative chain."""
    chain = PinChain(records(random_chain(seed, base, conservative=True)))
    states = chain.run(T_FINAL, t_eval=np.linspace(0.0, T_FINAL, 5))
    E = np.array([chain.energy(s) for s in states])
    s0 = states[0]
    T0 = pin.computeKineticEnergy(chain.model, chain.data, s0.q, s0.v)
    scale = T0 + G * sum(b.mass for b in chain.scene.bodies)  # T and m g (1 m)
    assert np.abs(E - E[0]).max() < ENERGY_RTOL * scale
    # the torque rotors' absolute spins are constant without an axial torque (eq 29)
    p0 = [r.spin for r in chain.rotors(s0)]
    np.testing.assert_allclose([r.spin for r in chain.rotors(states[-1])], p0, rtol=1e-10)


@pytest.mark.parametrize("seed,base", [(0, "fixed"), (5, "free"), (7, "moving")])
@pytest.mark.slow
def test_oracle_rotor_spins(seed, base):
    """Eq (29): a torque rotor's absolute spin grows as L_i t / A_i whatever the carrier does;
    a speed rotor keeps its kappa_i'."""
    chain = PinChain(records(random_chain(seed, base)))
    moments = axis_moments_for(chain, seed)
    torque = dict(zip(chain.axis_names, moments))
    s0 = chain.initial_state()
    s1 = chain.run(T_FINAL, moments)[-1]
    rotors = {r.name: r for b in chain.scene.bodies for r in b.rotors}
    for r0, r1 in zip(chain.rotors(s0), chain.rotors(s1)):
        rotor = rotors[r0.name]
        if rotor.mode == "torque":
            assert r0.spin == pytest.approx(rotor.spin, abs=1e-12)
            want = rotor.spin + torque.get(rotor.name, 0.0) * T_FINAL / rotor.axial_inertia
            assert r1.spin == pytest.approx(want, abs=1e-8)
        else:
            assert r1.rate == rotor.spin


def _lagrange_chain(kappa: float, thetas, eps21: int) -> tuple[dict, list[float]]:
    """One or two Lagrange gyroscopes in a regular precession of eq (88)."""
    A, B, m, c, s = [0.004, 0.003], [0.015, 0.012], [1.0, 0.8], [0.1, 0.12], 0.25
    th = list(thetas)
    if len(th) == 1:  # heavy top: the first line of (88) with m^2 = 0
        dphi = [((B[0] - A[0]) * kappa * np.cos(th[0]) - m[0] * c[0] * G / kappa) / A[0]]
    else:
        r = np.sin(th[1]) / np.sin(th[0])
        dphi = [((B[0] - A[0] + m[1] * s * s + eps21 * m[1] * c[1] * s * r) * kappa
                 * np.cos(th[0]) - (m[0] * c[0] + m[1] * s) * G / kappa) / A[0],
                ((B[1] - A[1] + eps21 * m[1] * c[1] * s / r) * kappa * np.cos(th[1])
                 - m[1] * c[1] * G / kappa) / A[1]]
    d = {"name": "lagrange", "gravity": [0.0, 0.0, -G],
         "base": {"type": "fixed", "position": [0.0, 0.0, 0.0]}, "bodies": []}
    for k, theta in enumerate(th):
        psi = 0.4 + (0.0 if (k == 0 or eps21 > 0) else np.pi)
        body = {"name": f"top{k + 1}", "joint": {"type": "spherical"}, "mass": m[k],
                "com": [0.0, 0.0, c[k]], "inertia": {"axial": A[k], "transverse": B[k]},
                "initial": {"euler": [psi, theta, 0.0], "euler_rates": [kappa, 0.0, dphi[k]]}}
        if k < len(th) - 1:
            body["next_joint"] = [0.0, 0.0, s]
        d["bodies"].append(body)
    return d, dphi


@pytest.mark.parametrize("kappa,thetas,eps21", [
    (3.0, [0.6], 1), (-4.0, [2.0], 1),
    (3.0, [0.6, 0.9], 1), (3.0, [0.6, 0.9], -1), (5.0, [2.2, 1.2], -1),
])
@pytest.mark.slow
def test_oracle_regular_precession(kappa, thetas, eps21):
    """Eq (88) (THEORY section 4): started in it, theta_k and psi_k' stay constant."""
    d, _ = _lagrange_chain(kappa, thetas, eps21)
    chain = PinChain(records(d))
    down = rot.down_frame(np.array([0.0, 0.0, -1.0]))
    for s in chain.run(T_FINAL, t_eval=[0.3, 0.7, 1.0]):
        for k, b in enumerate(chain.bodies(s)):
            euler = rot.matrix_to_euler(b.rotation, down)
            rates = rot.omega_to_euler_rates(euler, b.angular_velocity, down)
            assert euler[1] == pytest.approx(thetas[k], abs=1e-9)
            assert rates[0] == pytest.approx(kappa, abs=1e-8)
            assert rates[1] == pytest.approx(0.0, abs=1e-8)


# ------------------------------------------------------ gyro_sim vs oracle
CASES = [(0, "fixed"), (1, "fixed"), (2, "fixed"), (3, "fixed"), (4, "fixed"),
         (5, "free"), (6, "free"), (7, "moving")]


def _gyro_scene(d: dict) -> Scene:
    return load_scene(d) if load_scene is not None else records(d)


def _rotor_rates(sim) -> dict[str, float]:
    js = sim.joint_states()
    return dict(zip(js.name, (float(x) for x in js.velocity)))


def _bodies_close(sim_bodies, ora_bodies, worst: dict) -> None:
    assert [b.name for b in sim_bodies] == [b.name for b in ora_bodies]
    for bs, bo in zip(sim_bodies, ora_bodies):
        for key in ("position", "rotation", "angular_velocity", "velocity"):
            err = float(np.abs(np.asarray(getattr(bs, key)) - getattr(bo, key)).max())
            worst[key] = max(worst.get(key, 0.0), err)
            assert err < STATE_ATOL, f"{bs.name}.{key}: |gyro_sim - oracle| = {err:.3e}"


def _wrenches_close(sim_wrenches, ora_wrenches, rtol: float, worst: dict, tag: str) -> None:
    assert [w.joint for w in sim_wrenches] == [w.joint for w in ora_wrenches]
    f_scale = max(1.0, max(np.linalg.norm(w.force) for w in ora_wrenches))
    m_scale = max(f_scale * 1.0, max(np.linalg.norm(w.moment) for w in ora_wrenches))  # 1 m arm
    for ws, wo in zip(sim_wrenches, ora_wrenches):
        ef = float(np.abs(np.asarray(ws.force) - wo.force).max()) / f_scale
        em = float(np.abs(np.asarray(ws.moment) - wo.moment).max()) / m_scale
        worst[f"{tag} force"] = max(worst.get(f"{tag} force", 0.0), ef)
        worst[f"{tag} moment"] = max(worst.get(f"{tag} moment", 0.0), em)
        assert ef < rtol, f"{ws.joint}: R^k differs by {ef:.3e} (relative to {f_scale:.3g} N)"
        assert em < rtol, f"{ws.joint}: L^k differs by {em:.3e} (relative to {m_scale:.3g} N m)"


def _joint_closure(scene: Scene, wrenches, moments: dict[str, float]) -> None:
    """Spherical joint: L^k = 0; hinge: e^k . L^k = its command (eq 51); free base: R^1 = L^1 = 0."""
    scale = max(1.0, max(np.linalg.norm(w.force) for w in wrenches))
    for k, (body, w) in enumerate(zip(scene.bodies, wrenches)):
        if k == 0 and scene.base.type == "free":
            np.testing.assert_allclose(w.force, 0.0, atol=WRENCH_RTOL * scale)
            np.testing.assert_allclose(w.moment, 0.0, atol=WRENCH_RTOL * scale)
        elif body.joint.type == "spherical":
            np.testing.assert_allclose(w.moment, 0.0, atol=WRENCH_RTOL * scale)
        else:  # the axis has the same components in the parent's and the body's frame
            assert _unit(body.joint.axis) @ np.asarray(w.moment) == pytest.approx(
                moments[body.name], abs=WRENCH_RTOL * scale)


@pytest.mark.parametrize("seed,base", CASES)
@pytest.mark.slow
def test_random_chain_matches_oracle(seed, base):
    d = random_chain(seed, base)
    scene = _gyro_scene(d)
    chain = PinChain(records(d))
    moments = axis_moments_for(chain, seed)
    sim = Simulator(scene, **SIM_OPTIONS)
    assert list(sim.axis_names) == chain.axis_names
    sim.set_axis_moments(moments.tolist())
    named = dict(zip(chain.axis_names, moments))
    worst: dict[str, float] = {}  # largest discrepancy per quantity, printed with -s

    # t = 0: same initial state (the scene's reading) and the same reactions
    s0 = chain.initial_state()
    _bodies_close(sim.body_states(), chain.bodies(s0), worst)
    w0 = sim.wrenches()
    assert all(w.frame == w.joint for w in w0)
    _wrenches_close(w0, chain.reactions(s0, moments), WRENCH_RTOL, worst, "t=0")
    _joint_closure(scene, w0, named)

    # t = 1 s: each engine integrates on its own
    sim.advance(T_FINAL)
    assert sim.time == pytest.approx(T_FINAL)
    s1 = chain.run(T_FINAL, moments)[-1]
    sim_bodies = sim.body_states()
    _bodies_close(sim_bodies, chain.bodies(s1), worst)
    rates = _rotor_rates(sim)
    for r in chain.rotors(s1):
        err = abs(rates[r.name] - r.rate)
        worst["rotor rate"] = max(worst.get("rotor rate", 0.0), err)
        assert err < STATE_ATOL, f"rotor {r.name}: kappa' differs by {err:.3e}"
    w1 = sim.wrenches()
    _wrenches_close(w1, chain.reactions(s1, moments), WRENCH_TRAJ_RTOL, worst, "t=1 traj")
    # ... and the oracle's reactions on gyro_sim's own state at t = 1 s: pure algebra again
    s1_sim = chain.state_from_bodies(sim.time, sim_bodies, rates)
    _wrenches_close(w1, chain.reactions(s1_sim, moments), WRENCH_RTOL, worst, "t=1 same state")
    _joint_closure(scene, w1, named)
    print(f"{seed}-{base}: " + ", ".join(f"{k} {v:.1e}" for k, v in worst.items()))


@pytest.mark.parametrize("seed,base", CASES)
def test_loader_reads_random_chain_like_oracle(seed, base):
    """load_scene and this file's own reading of the scene dict agree (inertia_com -> A at O^k)."""
    d = random_chain(seed, base)
    got, want = load_scene(d), records(d)
    assert got.base.type == want.base.type
    np.testing.assert_allclose(got.base.position, want.base.position)
    np.testing.assert_allclose(got.gravity, want.gravity)
    for bg, bw in zip(got.bodies, want.bodies, strict=True):
        assert (bg.name, bg.joint.type) == (bw.name, bw.joint.type)
        np.testing.assert_allclose(bg.inertia, bw.inertia, rtol=1e-14, atol=1e-15)
        np.testing.assert_allclose(bg.com, bw.com)
        assert len(bg.rotors) == len(bw.rotors)
