"""Synthetic scenes for benchmarks: uniform chains of any length, and the same links hung as trees."""
from __future__ import annotations

LINK = 0.2  # m, joint to joint
MASS = 1.0  # kg per link


def spherical_chain(n: int, *, gravity: bool = True, rotors: bool = False, zero_features: bool = False) -> dict:
    """A chain of n identical rod-like links on spherical joints, started off the vertical.

    zero_features: gravity [0, 0, 0] and rotors of zero spin are present but inert, to
    measure what a feature costs when the scene has it (compare with gravity/rotors False).
    """
    bodies = []
    for k in range(n):
        b = {
            "name": f"link{k + 1}",
            "joint": {"type": "spherical"},
            "mass": MASS,
            "com": [0.0, 0.0, LINK / 2],
            "inertia": {"axial": 1e-3, "transverse": MASS * LINK**2 / 3},
            "initial": {"euler": [0.3 * k, 0.4 + 0.05 * k, 0.0], "euler_rates": [1.0, 0.0, 2.0]},
        }
        if k < n - 1:
            b["next_joint"] = [0.0, 0.0, LINK]
        if rotors or zero_features:
            b["rotors"] = [
                {
                    "name": f"rotor{k + 1}",
                    "axis": [0.0, 0.0, 1.0],
                    "position": [0.0, 0.0, LINK / 2],
                    "mass": 0.1,
                    "axial_inertia": 1e-4,
                    "transverse_inertia": 6e-5,
                    "mode": "torque",
                    "spin": 0.0 if zero_features else 100.0,
                }
            ]
        bodies.append(b)
    scene = {"name": f"spherical chain n={n}", "base": {"type": "fixed"}, "bodies": bodies}
    if gravity or zero_features:
        scene["gravity"] = [0.0, 0.0, 0.0] if zero_features else [0.0, 0.0, -9.81]
    return scene


def tree_of_links(n: int, branching: int, **options) -> dict:
    """The spherical chain of `spherical_chain(n, **options)` hung as a tree: body k from body
    (k - 1) // branching, at its parent's tip (branching 1: the chain itself, as it is written;
    2: a binary tree; n: a hub carrying the n - 1 others)."""
    scene = spherical_chain(n, **options)
    if branching == 1:
        return scene
    tip = scene["bodies"][0].get("next_joint", [0.0, 0.0, 0.2])
    for k, body in enumerate(scene["bodies"]):
        body.pop("next_joint", None)
        if k:
            body["parent"] = scene["bodies"][(k - 1) // branching]["name"]
            body["joint"]["at"] = list(tip)
    return scene
