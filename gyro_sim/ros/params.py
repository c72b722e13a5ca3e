"""The node's parameters: names, types, defaults, documentation and validation (no rclpy here).

`PARAMETERS` is the single table the node declares from (with descriptors) and `validate`
turns the values it got into a `NodeConfig`, or raises `ParameterError` naming every
parameter that is wrong and why, before anything is created or published.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path

#: largest physics rate accepted (Hz): beyond it one step is shorter than a Python call
MAX_PHYSICS_RATE = 100_000.0
#: relative tolerance on physics_rate / publish_rate being a whole number of steps
RATIO_TOLERANCE = 1e-9


class ParameterError(ValueError):
    """One or more parameters are invalid; the message lists them all, one per line."""


@dataclass(frozen=True)
class Parameter:
    name: str
    kind: type  # float, str or bool
    default: object
    description: str
    low: float | None = None  # inclusive bounds of numbers (descriptor ranges)
    high: float | None = None


PARAMETERS: tuple[Parameter, ...] = (
    Parameter("scene", str, "hinge_chain", "scene file (YAML), or the name of a shipped scene in config/"),
    Parameter("physics_rate", float, 1000.0, "physics steps per simulated second (Hz); 1/physics_rate is the step",
              1.0, MAX_PHYSICS_RATE),
    Parameter("publish_rate", float, 100.0,
              "publications per simulated second (Hz); physics_rate / publish_rate must be a whole number",
              0.01, MAX_PHYSICS_RATE),
    Parameter("real_time_factor", float, 1.0, "simulated seconds per wall second; 0 = as fast as possible",
              0.0, 1000.0),
    Parameter("integrator", str, "rk4", "rk4 | dop853 | radau | lie4 (fixed-step methods take one step per physics step)"),
    Parameter("backend", str, "auto", "dynamics: auto (numba-compiled when numba is installed, else numpy) | numba | numpy"),
    Parameter("rtol", float, 1e-8, "relative tolerance of adaptive integrators", 1e-14, 1.0),
    Parameter("atol", float, 1e-10, "absolute tolerance of adaptive integrators", 0.0, 1.0),
    Parameter("record", str, "", "MCAP file to record every published message and command to; empty = no recording"),
    Parameter("command_timeout", float, 0.5,
              "simulated seconds without a good command after which the axis moments fall back to zero", 1e-3, 1e9),
    Parameter("duration", float, 0.0, "simulated seconds to run, then exit; 0 = until shut down", 0.0, 1e9),
    Parameter("publish_wrenches", bool, True, "publish ~/wrench/<joint> (computed only while someone listens or records)"),
    Parameter("publish_poses", bool, True, "publish ~/poses (computed only while someone listens or records)"),
    Parameter("stats_file", str, "", "write the run's timing statistics as JSON to this file at exit; empty = none"),
)


@dataclass(frozen=True)
class NodeConfig:
    """Validated parameters, plus what follows from them."""

    scene_path: Path
    scene: object  # gyro_sim.core.scene.Scene
    physics_rate: float
    publish_rate: float
    real_time_factor: float
    integrator: str
    backend: str
    rtol: float
    atol: float
    record: str
    command_timeout: float
    duration: float
    publish_wrenches: bool
    publish_poses: bool
    stats_file: str

    @property
    def dt(self) -> float:
        """The physics step (simulated s)."""
        return 1.0 / self.physics_rate

    @property
    def steps_per_publish(self) -> int:
        return int(round(self.physics_rate / self.publish_rate))

    def as_dict(self) -> dict:
        """The parameters as given (for the log's metadata)."""
        return {p.name: getattr(self, p.name) if p.name != "scene" else str(self.scene_path) for p in PARAMETERS}


def _number_problem(p: Parameter, v) -> str | None:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return f"{p.name}: expected a number, got {v!r}"
    if not math.isfinite(v):
        return f"{p.name}: must be finite, got {v!r}"
    if p.low is not None and v < p.low:
        return f"{p.name}: must be >= {p.low:g}, got {v!r}"
    if p.high is not None and v > p.high:
        return f"{p.name}: must be <= {p.high:g}, got {v!r}"
    return None


def validate(values: dict) -> NodeConfig:
    """Check every parameter (missing ones take their default); raise ParameterError listing
    all problems, or return the NodeConfig with the scene loaded."""
    from ..core.integrators import INTEGRATORS
    from ..core.scene_load import SceneError, load_scene
    from ..paths import find_scene

    v = {p.name: values.get(p.name, p.default) for p in PARAMETERS}
    problems = []
    for p in PARAMETERS:
        if p.kind is float:
            msg = _number_problem(p, v[p.name])
            if msg:
                problems.append(msg)
            else:
                v[p.name] = float(v[p.name])
        elif p.kind is bool and not isinstance(v[p.name], bool):
            problems.append(f"{p.name}: expected true or false, got {v[p.name]!r}")
        elif p.kind is str and not isinstance(v[p.name], str):
            problems.append(f"{p.name}: expected a string, got {v[p.name]!r}")
    bad = {m.split(":")[0] for m in problems}
    if not {"physics_rate", "publish_rate"} & bad:
        ratio = v["physics_rate"] / v["publish_rate"]
        if ratio < 1 - RATIO_TOLERANCE:
            problems.append(f"publish_rate: must not exceed physics_rate ({v['physics_rate']:g} Hz), got {v['publish_rate']:g}")
        elif abs(ratio - round(ratio)) > RATIO_TOLERANCE * ratio:
            lo, hi = v["physics_rate"] / math.ceil(ratio), v["physics_rate"] / math.floor(ratio)
            problems.append(
                f"publish_rate: physics_rate / publish_rate = {ratio:g} must be a whole number of physics steps "
                f"(with physics_rate {v['physics_rate']:g}: e.g. publish_rate {lo:g} or {hi:g})"
            )
    if "integrator" not in bad and v["integrator"] not in INTEGRATORS:
        problems.append(f"integrator: unknown {v['integrator']!r}; valid: {', '.join(INTEGRATORS)}")
    if "backend" not in bad:
        from ..core.fast import BACKENDS, available

        if v["backend"] not in BACKENDS:
            problems.append(f"backend: unknown {v['backend']!r}; valid: {', '.join(BACKENDS)}")
        elif v["backend"] == "numba" and not available():
            problems.append("backend: numba is not installed (use auto or numpy)")
    scene = scene_path = None
    if "scene" not in bad:
        if not v["scene"].strip():
            problems.append("scene: empty; give a scene file or a shipped scene name")
        else:
            try:
                scene_path = find_scene(v["scene"])
                scene = load_scene(scene_path)
            except FileNotFoundError as exc:
                problems.append(f"scene: {exc}")
            except SceneError as exc:
                problems.append(f"scene: {scene_path}: {exc}")
    for name in ("record", "stats_file"):
        if name not in bad and v[name]:
            parent = Path(v[name]).expanduser().resolve().parent
            if not parent.is_dir():
                problems.append(f"{name}: directory {parent} does not exist")
            elif not os.access(parent, os.W_OK):
                problems.append(f"{name}: directory {parent} is not writable")
    if "record" not in bad and v["record"]:
        try:
            import mcap  # noqa: F401

            from ..io import mcap_log  # noqa: F401
        except ImportError as exc:
            problems.append(f"record: recording needs the mcap package ({exc})")
    if problems:
        raise ParameterError("\n".join(problems))
    v = dict(v)
    v["record"] = str(Path(v["record"]).expanduser().resolve()) if v["record"] else ""
    del v["scene"]
    return NodeConfig(scene_path=scene_path, scene=scene, **v)
