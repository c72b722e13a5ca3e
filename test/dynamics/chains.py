"""Random, physically valid chain scenes (dicts in the scene-file format) for tests."""
import numpy as np


def _inertia_com(rng, scale):
    """A random inertia about the centre of mass obeying the triangle inequality."""
    a, b = rng.uniform(0.5, 1.0, 2)
    c = rng.uniform(abs(a - b) + 0.05, a + b - 0.05)
    Q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    return (Q @ np.diag([a, b, c]) @ Q.T * scale).tolist()


def random_chain(seed, *, base="fixed", commands=True, speed_rotors=True, n=None, gravity=True):
    rng = np.random.default_rng(seed)
    n = n or int(rng.integers(2, 6))
    bodies = []
    for k in range(n):
        hinge = k > 0 and rng.random() < 0.5
        if k == 0 and base != "free":
            hinge = rng.random() < 0.3
        b = {
            "name": f"b{k}",
            "joint": {"type": "hinge", "axis": rng.normal(size=3).tolist()} if hinge else {"type": "spherical"},
            "mass": float(rng.uniform(0.2, 1.5)),
            "com": (rng.normal(size=3) * 0.05 + [0, 0, 0.08]).tolist(),
            "inertia_com": _inertia_com(rng, 0.01),
            "initial": {"angle": float(rng.normal()), "rate": float(rng.normal())}
            if hinge
            else {"euler": rng.normal(size=3).tolist(), "euler_rates": rng.normal(size=3).tolist()},
        }
        if k < n - 1:
            b["next_joint"] = (rng.normal(size=3) * 0.05 + [0, 0, 0.15]).tolist()
        rotors = []
        if rng.random() < 0.6:
            rotors.append(
                {
                    "name": f"r{k}t",
                    "axis": rng.normal(size=3).tolist(),
                    "position": (rng.normal(size=3) * 0.03).tolist(),
                    "mass": 0.05,
                    "axial_inertia": 2e-4,
                    "transverse_inertia": 1.2e-4,
                    "mode": "torque",
                    "spin": float(rng.uniform(-50, 50)),
                    "actuated": bool(commands and rng.random() < 0.7),
                }
            )
        if speed_rotors and rng.random() < 0.5:
            rotors.append(
                {
                    "name": f"r{k}s",
                    "axis": rng.normal(size=3).tolist(),
                    "position": (rng.normal(size=3) * 0.03).tolist(),
                    "mass": 0.05,
                    "axial_inertia": 2e-4,
                    "transverse_inertia": 1.2e-4,
                    "mode": "speed",
                    "spin": float(rng.uniform(-40, 40)),
                }
            )
        if rotors:
            b["rotors"] = rotors
        bodies.append(b)
    scene = {"name": f"random chain {seed}", "base": {"type": base}, "bodies": bodies}
    if base == "free":
        scene["base"]["velocity"] = rng.normal(size=3).tolist()
    if gravity:
        scene["gravity"] = [0.0, 0.0, -9.81]
    return scene
