"""A geared motor against MuJoCo's armature on a fast turntable (docs/models.md, "The geared
motor against the armature").

A SCARA-like arm: the upper arm turns freely about the vertical on a fixed base, spinning at
`spin`; the forearm turns about a parallel hinge at its end, driven by a constant moment, its
motor's rotor (axial inertia J, gear G) on the upper arm and coaxial with the elbow. The
armature J G^2 alone drops the rotor's own spin J G phi' about an axis that turns with the
upper arm: the upper arm does not take its reaction, and the two models part. Both runs share
the reflected inertia J G^2; the gear sets how much of it is coupling (J G = J G^2 / G).

    python examples/geared_vs_armature.py                  # the table of docs/models.md
    python examples/geared_vs_armature.py --seconds 0.5 --gears 5 50 --spins 0 20

Prints a markdown table: for each initial spin of the upper arm and gear, the elbow's angle
and the upper arm's rate at the end with the motor and with the armature, and their
differences.
"""
from __future__ import annotations

import argparse
import sys

#: the reflected inertia J G^2 (kg m^2) of every run, the arm's moment (N m), the fork's spring (N m/rad)
REFLECTED, MOMENT, STIFFNESS = 0.02, 0.2, 20.0


def scene(gear: float | None, spin: float) -> dict:
    """The turntable spinning at `spin` (rad/s), the tilting fork on its spring, and the arm with
    its geared motor of `gear` on the fork (None: the armature J G^2 instead)."""
    wrist = {"type": "hinge", "axis": [0.0, 1.0, 0.0]}
    if gear is None:
        wrist["armature"] = REFLECTED
    else:
        wrist["motor"] = {"inertia": REFLECTED / gear ** 2, "gear": gear}
    return {
        "name": "turntable_fork_arm",
        "base": {"type": "fixed"},
        "bodies": [
            {"name": "turntable", "joint": {"type": "hinge", "axis": [0.0, 0.0, 1.0]}, "mass": 10.0,
             "com": [0.0, 0.0, 0.0], "inertia_com": [[0.5, 0, 0], [0, 0.5, 0], [0, 0, 1.0]],
             "next_joint": [0.0, 0.0, 0.1], "initial": {"rate": spin}},
            {"name": "fork", "joint": {"type": "hinge", "axis": [1.0, 0.0, 0.0],
                                       "spring": {"stiffness": STIFFNESS}},
             "mass": 1.0, "com": [0.0, 0.0, 0.05], "inertia_com": [[0.004, 0, 0], [0, 0.004, 0], [0, 0, 0.002]],
             "next_joint": [0.0, 0.0, 0.1]},
            {"name": "arm", "joint": wrist, "mass": 0.5, "com": [0.0, 0.0, 0.1],
             "inertia_com": [[0.002, 0, 0], [0, 0.002, 0], [0, 0, 0.0005]]},
        ],
    }


def run(gear: float | None, spin: float, seconds: float) -> tuple[float, float]:
    """(the fork's largest tilt, the arm's angle) over `seconds` under the arm's constant moment."""
    from gyro_sim import Simulator

    sim = Simulator(scene(gear, spin), integrator="dop853", rtol=1e-12, atol=1e-12)
    sim.set_axis_moments([0.0, 0.0, MOMENT])
    tilt = 0.0
    for _ in range(STEPS):
        sim.advance(seconds / STEPS)
        tilt = max(tilt, abs(float(sim.state[sim.model.i_phi][1])))
    return tilt, float(sim.state[sim.model.i_phi][2])


#: samples of the fork's tilt over a run
STEPS = 200


def table(gears, spins, seconds: float) -> list[dict]:
    """One row per (spin, gear): the end states with the motor and with the armature."""
    rows = []
    for spin in spins:
        tilt_a, arm_a = run(None, spin, seconds)
        for gear in gears:
            tilt, arm = run(gear, spin, seconds)
            rows.append({"spin": spin, "gear": gear, "tilt": tilt, "tilt_armature": tilt_a, "arm": arm,
                         "arm_armature": arm_a})
    return rows


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=1.0, help="simulated time (s)")
    parser.add_argument("--gears", type=float, nargs="+", default=[5.0, 20.0, 100.0])
    parser.add_argument("--spins", type=float, nargs="+", default=[0.0, 10.0, 30.0],
                        help="initial rates of the upper arm (rad/s)")
    args = parser.parse_args(argv)
    print(f"J G^2 = {REFLECTED} kg m^2, arm moment {MOMENT} N m, fork spring {STIFFNESS} N m/rad, "
          f"{args.seconds:g} s")
    print("| turntable (rad/s) | gear | fork's largest tilt, motor (rad) | same, armature (rad) "
          "| arm's angle, motor - armature (rad) |")
    print("|---:|---:|---:|---:|---:|")
    for r in table(args.gears, args.spins, args.seconds):
        print(f"| {r['spin']:g} | {r['gear']:g} | {r['tilt']:.2e} | {r['tilt_armature']:.2e} "
              f"| {r['arm'] - r['arm_armature']:.2e} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
