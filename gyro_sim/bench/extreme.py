"""Scenes of the stability report: stiff and extreme cases, built from a few parameters.

Each builder returns a scene mapping (docs/scene-format.md, loadable by `load_scene`) and
says in its docstring what makes the case hard. The numbers that matter (frequency ratio,
mass ratio, Kapitza margin) are arguments, so the report and the tests can state them and
move them. Some cases are shipped as files too (`config/stiff_*.yaml`,
`config/extreme_*.yaml`, written by ``python -m gyro_sim.bench.extreme config``).

Cases (stiff and extreme):

- :func:`fast_rotor`: a top on a fast rotor, nutation >= 1e4 x precession frequency;
- :func:`mass_ratio_chain`: a 3-body chain whose tip is 1e-6 or 1e6 times its neighbour;
- :func:`gyro_sim.bench.scenes.spherical_chain`: long chains (n = 100, 200);
- :func:`kapitza`: an inverted rod on a vibrating base, above or below Kapitza's condition;
- :func:`nutating_top`: a small scene for the long-horizon (1e6 steps) energy drift;
- :func:`looping_top`, :func:`near_spherical_top`, :func:`thin_rod_top`, :func:`flat_disc_top`:
  near-singular attitudes (the axis through theta = 0 and pi) and inertia (A ~ B, A << B,
  A ~ 2 B_c);
- :func:`abrupt_commands`: the hinge chain with step moments 1e3 x the gravity torque.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import yaml

from gyro_sim.paths import find_scene

G = 9.81  # m/s^2, the shipped scenes' gravity

# --- fast rotor (config/fast_rotor.yaml's top) ------------------------------------------
#: the top of config/fast_rotor.yaml: stem and disc, about the tip O^1
_TOP_MASS, _TOP_C = 0.4, (0.1 * 0.06 + 0.3 * 0.08) / 0.4  # kg, m (stem + disc)
_DISC_A = 2.4e-4  # kg m^2, the disc's axial inertia
_TOP_B = 4.80625e-4 + 1.225e-4 + 0.3 * 0.08**2  # transverse inertia about the tip

# --- Kapitza's pendulum (config/vibrating_base.yaml's rod) --------------------------------
KAPITZA_MASS = 0.2  # kg
KAPITZA_C = 0.1  # m, suspension point to centre of mass
KAPITZA_I = 2.67167e-3  # kg m^2, about the suspension point
KAPITZA_AMPLITUDE = 0.01  # m, vertical
#: initial tilt from the upward vertical (rad)
KAPITZA_TILT = 0.1


def load_dict(name: str) -> dict[str, Any]:
    """A shipped scene (config/<name>.yaml) as a plain mapping, to be modified."""
    with open(find_scene(name), encoding="utf-8") as f:
        return yaml.safe_load(f)


# ------------------------------------------------------------------------------ fast rotor
def fast_rotor_spin(ratio: float) -> float:
    """Rotor spin p (rad/s) for which nutation / precession frequency = `ratio`.

    For a fast top, nutation w_n = A p / B and precession w_p = m g c / (A p) (B about the
    tip), so w_n / w_p = (A p)^2 / (B m g c).
    """
    return math.sqrt(ratio * _TOP_B * _TOP_MASS * G * _TOP_C) / _DISC_A


def fast_rotor_frequencies(spin: float) -> tuple[float, float]:
    """(nutation, precession) angular frequencies (rad/s) of the fast top at rotor spin p."""
    return _DISC_A * spin / _TOP_B, _TOP_MASS * G * _TOP_C / (_DISC_A * spin)


def fast_rotor(ratio: float = 1e4) -> dict[str, Any]:
    """config/fast_rotor.yaml with the rotor spun up until nutation = `ratio` x precession.

    Gyroscopic stiffness: the fast nutation (a pair of eigenvalues +-i w_n on the imaginary
    axis) sets the step of an explicit method although its amplitude is tiny; the slow
    precession is the motion of interest.
    """
    sd = load_dict("fast_rotor")
    p = fast_rotor_spin(ratio)
    w_n, w_p = fast_rotor_frequencies(p)
    sd["name"] = f"fast rotor: nutation {w_n:.0f} rad/s = {ratio:.0e} x precession {w_p:.3g} rad/s"
    sd["bodies"][0]["rotors"][0]["spin"] = float(p)
    return sd


def fast_rotor_precession(ratio: float = 1e4) -> dict[str, Any]:
    """:func:`fast_rotor` started exactly in its slow regular precession (eq 88, n = 1).

    The slow root of A phi' = (B - A) kappa cos th - m c g / kappa - lambda with phi' = 0
    (the carrier does not spin, the rotor does): kappa = -m c g / lambda to first order. The
    motion is exact and known (theta, psi' constant), the fast nutation is not excited: a
    stiff problem in the textbook sense, whose fast mode has zero amplitude.
    """
    from gyro_sim.analytic import lagrange as lg
    from gyro_sim.scene.load import load_scene

    sd = fast_rotor(ratio)
    chain = lg.LagrangeChain.from_scene(load_scene(sd))
    th = float(sd["bodies"][0]["initial"]["euler"][1])
    A, B, lam = float(chain.A[0]), float(chain.B[0]), float(chain.lam[0])
    mcg = float(chain.m[0] * chain.c[0] * chain.g)
    a = (B - A) * math.cos(th)
    disc = math.sqrt(lam * lam + 4.0 * a * mcg)
    kappa = min((lam + disc) / (2 * a), (lam - disc) / (2 * a), key=abs)
    euler, rates = lg.regular_precession_state(chain, [th], kappa)
    sd["bodies"][0]["initial"] = {"euler": [float(x) for x in euler[0]],
                                  "euler_rates": [float(x) for x in rates[0]]}
    sd["name"] += ", in regular precession"
    return sd


# --------------------------------------------------------------------------- mass ratios
def mass_ratio_chain(ratio: float) -> dict[str, Any]:
    """config/light_tip.yaml with the tip `ratio` times as heavy as its neighbour.

    ratio = 1e-6 is the shipped light tip (a pendulum that barely loads the chain); ratio =
    1e6 hangs a heavy tip on two nearly massless links: the mass matrix is then nearly
    singular (the links can turn about the line from O^1 to the tip at almost no cost) and
    that "elbow" mode is fast: stiff.
    """
    sd = load_dict("light_tip")
    lower, tip = sd["bodies"][1], sd["bodies"][2]
    base_mass, base_inertia = 0.3, {"axial": 1.5e-5, "transverse": 1.0075e-3}  # tip at ratio 1
    tip["mass"] = float(lower["mass"] * ratio)
    scale = tip["mass"] / base_mass
    tip["inertia"] = {key: float(value * scale) for key, value in base_inertia.items()}
    kind = "light" if ratio < 1 else "heavy"
    sd["name"] = f"three-body chain with a {kind} tip (mass ratio {ratio:.0e})"
    return sd


# ------------------------------------------------------------------------------- Kapitza
def kapitza_threshold_frequency(amplitude: float = KAPITZA_AMPLITUDE) -> float:
    """The base frequency f (Hz) at which (a Omega)^2 = 2 g I / (m c), Omega = 2 pi f."""
    return math.sqrt(2.0 * G * KAPITZA_I / (KAPITZA_MASS * KAPITZA_C)) / amplitude / (2 * math.pi)


def kapitza_margin(frequency: float, amplitude: float = KAPITZA_AMPLITUDE) -> float:
    """(a Omega)^2 / (2 g I / (m c)): above 1 the inverted rod is stable (Kapitza)."""
    return (amplitude * 2 * math.pi * frequency) ** 2 / (2.0 * G * KAPITZA_I / (KAPITZA_MASS * KAPITZA_C))


def kapitza(margin: float, tilt: float = KAPITZA_TILT) -> dict[str, Any]:
    """The rod of config/vibrating_base.yaml, inverted (`tilt` rad from the upward vertical),
    on a base vibrating vertically with amplitude 1 cm at the frequency whose Kapitza
    margin (a Omega)^2 / (2 g I / (m c)) is `margin`: stable above 1, unstable below.
    """
    sd = load_dict("vibrating_base")
    f = kapitza_threshold_frequency() * math.sqrt(margin)
    sd["base"]["motion"] = {"type": "sine", "amplitude": [0.0, 0.0, KAPITZA_AMPLITUDE], "frequency": float(f)}
    sd["bodies"][0]["initial"] = {"euler": [0.0, math.pi - tilt, 0.0], "euler_rates": [0.0, 0.0, 0.0]}
    sd["name"] = f"Kapitza pendulum, base at {f:.1f} Hz (margin {margin:g})"
    return sd


# --------------------------------------------------------------------- small, generic tops
def _top(name: str, *, axial: float, transverse: float, c: float = 0.1, mass: float = 1.0,
         euler=(0.0, 0.6, 0.0), rates=(-3.0, 1.0, 40.0), inertia_com=None) -> dict[str, Any]:
    body: dict[str, Any] = {"name": "top", "joint": {"type": "spherical"}, "mass": mass,
                            "com": [0.0, 0.0, c]}
    if inertia_com is None:
        body["inertia"] = {"axial": axial, "transverse": transverse}
    else:
        body["inertia_com"] = inertia_com
    body["initial"] = {"euler": list(euler), "euler_rates": list(rates)}
    return {"name": name, "gravity": [0.0, 0.0, -G], "base": {"type": "fixed", "position": [0.0, 0.0, 0.0]},
            "bodies": [body]}


def nutating_top() -> dict[str, Any]:
    """The heavy top of config/heavy_top.yaml started off its regular precession (theta' = 1
    rad/s, spin 40 rad/s): a generic nutating motion, one body, for the long-horizon runs."""
    return _top("heavy top, nutating (long horizon)", axial=0.004, transverse=0.015)


def looping_top() -> dict[str, Any]:
    """A spinning heavy top started hanging (theta = 0 exactly) and thrown hard enough to loop
    over the top: its axis passes through theta = 0 and theta = pi every turn, where the
    Euler angles are singular (the state is a quaternion: nothing should happen)."""
    # loops when B theta'^2 / 2 > 2 m g c: theta' > sqrt(4 m g c / B) = 16.2 rad/s
    return _top("looping top: the axis through theta = 0 and pi", axial=0.004, transverse=0.015,
                euler=(0.0, 0.0, 0.0), rates=(0.0, 20.0, 30.0))


def near_spherical_top(gap: float = 1e-9) -> dict[str, Any]:
    """A heavy top whose inertia about its centre of mass is spherical to `gap` (A ~ B): the
    principal axes of the transverse plane are undefined; nothing should depend on them."""
    b = 0.01
    return _top(f"near-spherical top (A = B (1 + {gap:g}))", axial=0.0, transverse=0.0, c=0.02,
                inertia_com=[[b, 0.0, 0.0], [0.0, b, 0.0], [0.0, 0.0, b * (1.0 + gap)]],
                rates=(-3.0, 1.0, 40.0))


def thin_rod_top(ratio: float = 1e-8) -> dict[str, Any]:
    """A heavy top that is a thin rod: axial inertia `ratio` x transverse, spinning about its
    axis. The mass matrix is ill-conditioned (condition ~ 1 / ratio)."""
    B = 0.015
    return _top(f"thin rod (A = {ratio:g} B)", axial=B * ratio, transverse=B, rates=(-3.0, 1.0, 40.0))


def flat_disc_top(gap: float = 1e-9) -> dict[str, Any]:
    """A heavy top that is a flat disc: about its centre of mass A = 2 B (1 - gap), the limit
    of the triangle inequality."""
    b = 0.005
    return _top(f"flat disc (A_c = 2 B_c (1 - {gap:g}))", axial=0.0, transverse=0.0,
                inertia_com=[[b, 0.0, 0.0], [0.0, b, 0.0], [0.0, 0.0, 2.0 * b * (1.0 - gap)]],
                rates=(-3.0, 1.0, 40.0))


# ------------------------------------------------------------------------ abrupt commands
#: the step is this many times the gravity torque of each actuated axis's subtree
ABRUPT_FACTOR = 1e3


def abrupt_commands(factor: float = ABRUPT_FACTOR, scene: str = "hinge_chain") -> tuple[dict[str, Any], list[float]]:
    """A shipped straight chain (config/hinge_chain.yaml by default) and step axis moments of
    `factor` x each axis's gravity torque.

    Returns (scene mapping, moments in the scene's axis order: for the hinge chain wheel2, arm3,
    arm4; each body's hinge, then its actuated rotors, in chain order). The gravity torque of a
    hinge is m g times the horizontal lever of the subtree's centre of mass at rest along its
    body axis (sum of m c over the subtree); for a rotor, the gravity torque of the body carrying
    it (its subtree). A scene without gravity (a free chain in space) gets the torque of G (the
    shipped scenes' gravity) all the same: the size of its commands. Signs alternate, so the
    chain twists.
    """
    sd = load_dict(scene)
    bodies = sd["bodies"]

    def subtree_moment(k: int) -> float:  # sum m^q |r_com^q - O^k| along a straight chain
        total, offset = 0.0, 0.0
        for q in range(k, len(bodies)):
            b = bodies[q]
            total += b["mass"] * (offset + b["com"][2])
            for r in b.get("rotors", ()):
                total += r["mass"] * (offset + r["position"][2])
            offset += b.get("next_joint", [0.0, 0.0, 0.0])[2]
        return total * G

    levers = []
    for k, b in enumerate(bodies):
        levers += [subtree_moment(k)] * ((b["joint"]["type"] == "hinge")
                                         + sum(bool(r.get("actuated")) for r in b.get("rotors", ())))
    moments = [(-1) ** i * factor * m for i, m in enumerate(levers)]
    sd["name"] = f"{scene.replace('_', ' ')}, step moments {factor:g} x gravity torque"
    return sd, [float(m) for m in moments]


# ------------------------------------------------------------------------ shipped files
#: file name -> (builder, header comment). Not the heavy tip: no integrator gets through it at
#: the tight tolerances of test/dynamics/test_conservation.py (see the stability report).
SHIPPED: dict[str, tuple[Any, str]] = {
    "stiff_fast_rotor.yaml": (
        lambda: fast_rotor_precession(1e4),
        "The fast rotor of fast_rotor.yaml spun up until nutation = 1e4 x precession, started\n"
        "in its slow regular precession (eq 88): gyroscopic stiffness, exact solution known."),
    "extreme_kapitza_below.yaml": (
        lambda: kapitza(0.5),
        "Kapitza's pendulum BELOW the threshold: (a Omega)^2 = 0.5 x 2 g I / (m c). The\n"
        "inverted rod must fall (vibrating_base.yaml is the stable case, margin 3.77)."),
    "extreme_looping_top.yaml": (
        looping_top,
        "A spinning top thrown over the top: its axis passes through theta = 0 and pi (the\n"
        "Euler-angle singularities) every turn."),
}


def shipped_yaml(fname: str) -> str:
    """The text of the shipped scene file `fname` (a key of SHIPPED)."""
    build, header = SHIPPED[fname]
    header += ("\n\nGENERATED, do not edit by hand: written by `python -m gyro_sim.bench.extreme config`\n"
               f"from gyro_sim.bench.extreme.SHIPPED[{fname!r}]; test/bench checks it is unchanged.")
    comments = "".join(f"# {line}\n" if line else "#\n" for line in header.splitlines())
    # floats are written as repr: they read back exactly
    return comments + yaml.safe_dump(build(), sort_keys=False, default_flow_style=None, width=100)


def write_shipped(config_dir: str) -> list[str]:
    """Write the SHIPPED scenes into `config_dir`; the paths written."""
    paths = []
    for fname in SHIPPED:
        path = Path(config_dir) / fname
        path.write_text(shipped_yaml(fname), encoding="utf-8")
        paths.append(str(path))
    return paths


if __name__ == "__main__":
    import sys

    for written in write_shipped(sys.argv[1] if len(sys.argv) > 1 else "config"):
        print(written)
