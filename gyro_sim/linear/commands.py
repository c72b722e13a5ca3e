"""`gyro-sim linearize SCENE`: the linear model at a state, its eigenvalues and verdict."""
from __future__ import annotations

import argparse
import json
import math
import sys
import time

import numpy as np

from gyro_sim.linear.linearize import CHARTS, DISCRETE_METHODS, EQUILIBRIUM_TOL

LINEARIZE_EXAMPLES = """examples:
  gyro-sim linearize rw_pendulum
  gyro-sim linearize rw_pendulum --discrete 0.01 --json
  gyro-sim linearize heavy_top --state upright.yaml
  gyro-sim linearize arm_flywheel.xml --keyframe swing

--state FILE: a YAML mapping of body names to the scene's `initial` keys, e.g.
  pendulum: {angle: 3.14159, rate: 0.0}
The model is at the scene's initial state (or that one) with zero commands and the servos' initial
controls (a keyframe's ctrl) (docs/linearization.md)."""


def register(sub, bench) -> None:
    p = sub.add_parser("linearize", help="the linear model at a state: eigenvalues, stability verdict, controllability",
                       epilog=LINEARIZE_EXAMPLES, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("scene", metavar="SCENE", help="scene file, an MJCF or URDF model, or a shipped scene's name")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--keyframe", metavar="K", help="models only: the keyframe of the state")
    g.add_argument("--state", metavar="FILE", help="YAML: body name -> the scene's `initial` keys for that body")
    p.add_argument("--discrete", type=float, metavar="H", help="also the model of one step of H seconds")
    p.add_argument("--method", default="zoh", choices=DISCRETE_METHODS,
                   help="the step of --discrete: zoh (exact, input held), or a fixed-step integrator's")
    p.add_argument("--chart", default="world", choices=CHARTS,
                   help="rotations: world (rotation vectors in world axes), body (co-rotating with a steady spin) "
                        "or frame (seen from a frame turning at --frame-rate)")
    p.add_argument("--frame-rate", type=float, nargs=3, metavar=("WX", "WY", "WZ"),
                   help="--chart frame: the frame's angular velocity, rad/s, world axes (a precession's rate)")
    p.add_argument("--rotor-angles", action="store_true", help="keep the rotor angles in the state (cyclic)")
    p.add_argument("--fd", action="store_true", help="central differences instead of the exact complex step")
    p.add_argument("--json", action="store_true", help="one JSON object on stdout")
    from gyro_sim.scene.commands import add_model_options

    add_model_options(p)
    p.set_defaults(fn=cmd_linearize)


def _fail(message: str) -> int:
    print(f"gyro-sim linearize: {message}", file=sys.stderr)
    return 2


def _with_state(scene, path: str):
    """The scene with the initial keys of `path` for the bodies it names (SceneError, OSError)."""
    import copy

    from gyro_sim.scene.load import SceneError, load_scene, parse_yaml, read_text_file

    data = parse_yaml(read_text_file(path), path)
    if not isinstance(data, dict) or not data:
        raise SceneError([f"--state {path}: must map body names to their `initial` keys"])
    source = copy.deepcopy(scene.source)
    bodies = {b.get("name"): b for b in source.get("bodies", [])}
    for name, initial in data.items():
        if name not in bodies:
            raise SceneError([f"--state {path}: no body named {name!r} (bodies: {', '.join(map(str, bodies))})"])
        if not isinstance(initial, dict):
            raise SceneError([f"--state {path}: {name}: must be a mapping of `initial` keys"])
        bodies[name]["initial"] = initial
    return load_scene(source)


def cmd_linearize(args) -> int:
    from gyro_sim.dynamics.model import compile_model, initial_state
    from gyro_sim.linear.linearize import LinearizationError, linearize
    from gyro_sim.paths import find_scene
    from gyro_sim.scene.commands import model_options
    from gyro_sim.scene.load import SceneError, load_scene

    if args.discrete is not None and not (args.discrete > 0 and math.isfinite(args.discrete)):
        return _fail(f"--discrete: the step must be a positive finite number of seconds, got {args.discrete}")
    try:
        scene = load_scene(find_scene(args.scene), **model_options(args))
        if args.state:
            scene = _with_state(scene, args.state)
    except (SceneError, FileNotFoundError, OSError) as exc:
        return _fail(str(exc) or type(exc).__name__)  # every problem of the file, as `run` lists them
    start = time.perf_counter()
    try:  # the scene's initial state, zero commands, the servos' initial controls (a keyframe's
        # ctrl): what Simulator.linearize() gives after a reset
        model = compile_model(scene)
        y = initial_state(model)
        spins = y[model.i_spin] if model.stateful else model.torque_p0
        lin = linearize(model, 0.0, y, spins, np.zeros(len(model.axis_names)), method="fd" if args.fd else "complex",
                        chart=args.chart, rotor_angles=args.rotor_angles, frame_rate=args.frame_rate,
                        controls=model.initial_controls)
        disc = lin.discrete(args.discrete, args.method) if args.discrete is not None else None
    except LinearizationError as exc:
        return _fail(str(exc))
    report = describe(lin, disc, scene.name)
    report["seconds"] = time.perf_counter() - start
    if args.json:
        json.dump(report, sys.stdout, indent=1)
        print()
    else:
        print(text(report))
    return 0


def _mode(ev: complex) -> dict:
    re, im = float(ev.real), float(ev.imag)
    return {"real": re, "imag": im, "frequency_hz": abs(im) / (2 * math.pi),
            "time_constant_s": (1.0 / abs(re)) if re != 0.0 else None}


def describe(lin, disc, name: str) -> dict:
    """The report as a plain mapping (the --json output)."""
    ev = lin.eigenvalues()
    out = {
        "scene": name, "t": lin.t, "chart": lin.chart, "method": lin.method, "evaluations": lin.evaluations,
        "state_names": list(lin.state_names), "input_names": list(lin.input_names),
        "is_equilibrium": lin.is_equilibrium, "equilibrium_residual": lin.equilibrium_residual,
        "eigenvalues": [_mode(e) for e in ev], "verdict": lin.verdict(), "tolerance": lin.tolerance,
        "largest_real_part": float(ev.real.max()) if len(ev) else None,
        "controllability_rank": lin.controllability_rank(), "states": len(lin.state_names),
        "notes": list(lin.notes), "linearization_seconds": lin.seconds,
    }
    if disc is not None:
        z = np.linalg.eigvals(disc.Ad)
        z = z[np.argsort(-np.abs(z))]
        out["discrete"] = {"h": disc.h, "method": disc.method,
                           "spectral_radius": float(np.max(np.abs(z))) if len(z) else 0.0,
                           "eigenvalues": [{"real": float(v.real), "imag": float(v.imag), "abs": float(abs(v))}
                                           for v in z]}
    return out


def text(r: dict) -> str:
    how = "complex step" if r["method"] == "complex" else "central differences"
    lines = [(f"{r['scene']}: {r['states']} states, {len(r['input_names'])} inputs, at t = {r['t']:g} s "
              f"({r['chart']} chart, {how})"),
             "states: " + " ".join(r["state_names"]),
             "inputs: " + (" ".join(r["input_names"]) or "none")]
    lines += [f"note: {n}" for n in r["notes"]]
    lines.append("eigenvalues (largest real part first):")
    lines.append(f"  {'real':>13} {'imag':>13} {'frequency Hz':>13} {'time const s':>13}")
    for e in r["eigenvalues"]:
        tc = "inf" if e["time_constant_s"] is None else f"{e['time_constant_s']:.6g}"
        lines.append(f"  {e['real']:13.6g} {e['imag']:13.6g} {e['frequency_hz']:13.6g} {tc:>13}")
    if r["is_equilibrium"]:
        lines.append(f"verdict: {r['verdict']} (largest real part {r['largest_real_part']:.6g}; "
                     f"|real part| <= {r['tolerance']:.2g} counts as zero)")
    else:
        lines.append(f"verdict: none, not an equilibrium (max |f0| = {r['equilibrium_residual']:.3g} "
                     f"> {EQUILIBRIUM_TOL:g}): "
                     "the eigenvalues depend on the chart; try --chart body for a steady spin, "
                     "--chart frame for a precession")
    lines.append(f"controllability rank: {r['controllability_rank']} of {r['states']}")
    if "discrete" in r:
        d = r["discrete"]
        lines.append(f"discrete ({d['method']}, h = {d['h']:g} s): spectral radius {d['spectral_radius']:.9g}")
    lines.append(f"took {r['seconds']:.3f} s ({r['evaluations']} evaluations of the dynamics, "
                 f"{r['linearization_seconds']:.3f} s of it linearising)")
    return "\n".join(lines)
