"""The sweep file: loading, validation (every error names its key path) and the points.

    name: Kapitza pendulum over (amplitude, frequency)
    scene: vibrating_base            # a shipped scene, a path (relative to this file), or a mapping
    set:                             # fixed edits of the base scene, by key path
      bodies[0].initial.euler: [0.0, 3.0415926535897931, 0.0]
    grid:                            # the first key varies slowest
      base.motion.amplitude[2]: {linspace: [0.004, 0.02, 9]}
      base.motion.frequency: {logspace: [10.0, 100.0, 12]}    # geometric, from 10 to 100
      # also: [1.0, 2.0, 3.0] or {values: [...]}; run.step, run.integrator, ... vary the run
    # or, instead of grid:
    # random: {draws: 200, seed: 1, parameters: {bodies[0].com[2]: {uniform: [0.05, 0.1]}}}
    #   distributions: uniform [a, b], loguniform [a, b], normal [mean, std], choice [v, ...]
    run: {integrator: dop853, rtol: 1.0e-8, atol: 1.0e-10, step: 1.0e-3, horizon: 2.0, chunk: 0.01}
    measures: [final_state, max_tilt, max_deviation, drift, cpu_time]   # also exact_error, eigenvalues
    verdicts:
      - {name: stays_up, measure: max_tilt_rad, below: 1.5707963267948966}
    theory: {formula: kapitza, verdict: stays_up}          # see gyro_sim.sweep.theory
    map: {x: base.motion.frequency, y: base.motion.amplitude[2], verdict: stays_up}
    quick:                           # --quick: these replace the entries above
      grid: {base.motion.frequency: {logspace: [10.0, 100.0, 6]}}
      run: {horizon: 1.0}
    batch: 4                         # points per Dask task (default: about 4 tasks per worker)
    seed: 0                          # per-point seeds of a grid (random: random.seed)

Key paths are dotted mapping keys with list indices (``bodies[1].rotors[0].spin``,
``base.motion.amplitude[2]``); ``run.<option>`` varies the run itself. Every point's scene is
loaded and validated (:func:`gyro_sim.scene.load.load_scene`) before anything runs.
"""
from __future__ import annotations

import copy
import hashlib
import itertools
import json
import math
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
import yaml

from gyro_sim.errors import GyroSimError

__all__ = ["SweepError", "Sweep", "Point", "load_sweep", "set_path", "parse_path", "MEASURES", "RUN_DEFAULTS"]

#: what a point can measure (the columns each adds are in gyro_sim.sweep.point)
MEASURES = ("final_state", "max_tilt", "max_deviation", "exact_error", "drift", "cpu_time", "eigenvalues")
#: measures taken from the point's initial state alone: a sweep of only these simulates nothing
STATIC_MEASURES = ("eigenvalues", "cpu_time")
DEFAULT_MEASURES = ("final_state", "max_tilt", "max_deviation", "drift", "cpu_time")
#: scalar measure columns a verdict may test
VERDICT_MEASURES = {"max_tilt_rad": "max_tilt", "max_deviation_rad": "max_deviation",
                    "exact_error_rad": "exact_error", "max_drift": "drift", "max_real_eig": "eigenvalues"}
RUN_DEFAULTS: dict[str, Any] = {"integrator": "dop853", "rtol": 1e-8, "atol": 1e-10, "step": 1e-3,
                                "horizon": 1.0, "chunk": 0.01, "backend": "auto"}
RUN_FLOATS = ("rtol", "atol", "step", "horizon", "chunk")
DISTRIBUTIONS = ("uniform", "loguniform", "normal", "choice")
TOP_KEYS = ("name", "scene", "set", "grid", "random", "run", "measures", "verdicts", "theory", "map", "quick",
            "batch", "seed")
MAP_KINDS = ("heatmap", "largest", "histogram")
#: bounded input, as for scenes: at most this many points (a sweep of 1e6 points is a typo)
MAX_POINTS = 200_000
MAX_GRID_VALUES = 10_000
MAX_FILE_BYTES = 1_000_000


def simulates(measures) -> bool:
    """Whether measures need a run: not when every one is taken at the initial state."""
    return not set(measures) <= set(STATIC_MEASURES)


_SEGMENT = re.compile(r"([A-Za-z_][A-Za-z0-9_]*)((?:\[\d+\])*)")
_INDEX = re.compile(r"\[(\d+)\]")


class SweepError(GyroSimError, ValueError):
    """A sweep file that cannot be run. `errors` lists every problem as ``<key path>: <rule>``."""

    def __init__(self, errors: Sequence[str], path: str | None = None):
        self.errors = list(errors)
        self.path = path
        where = f"invalid sweep {path!r}" if path is not None else "invalid sweep"
        count = f"{len(self.errors)} error" + ("s" if len(self.errors) != 1 else "")
        super().__init__(f"{where} ({count}): " + "; ".join(self.errors))


# ------------------------------------------------------------------------------ key paths
def parse_path(text: str) -> list[str | int]:
    """``"bodies[1].rotors[0].spin"`` -> ``["bodies", 1, "rotors", 0, "spin"]``; ValueError if malformed."""
    if not isinstance(text, str) or not text:
        raise ValueError("not a key path")
    out: list[str | int] = []
    for part in text.split("."):
        m = _SEGMENT.fullmatch(part)
        if m is None:
            raise ValueError(f"malformed key path (segment {part!r}; write keys.like[0].this)")
        out.append(m.group(1))
        out += [int(i) for i in _INDEX.findall(m.group(2))]
    return out


def _fmt(path: Sequence[str | int]) -> str:
    s = ""
    for p in path:
        s += f"[{p}]" if isinstance(p, int) else (("." if s else "") + p)
    return s


def set_path(data: Any, path: Sequence[str | int], value: Any) -> None:
    """Set `value` at `path` in the nested mapping `data`. The container must exist; a list index
    must be in range; a mapping may get a new key (the scene's own validation names unknown keys).
    Raises KeyError with a message naming the part of the path that is missing."""
    node = data
    for i, key in enumerate(path):
        last = i == len(path) - 1
        where = _fmt(path[:i]) or "the scene"
        if isinstance(key, int):
            if not isinstance(node, list):
                raise KeyError(f"{where} is not a list")
            if key >= len(node):
                raise KeyError(f"{_fmt(path[:i + 1])}: index out of range ({where} has {len(node)})")
        else:
            if not isinstance(node, dict):
                raise KeyError(f"{where} is not a mapping")
            if key not in node and not last:
                has = ", ".join(map(str, node)) or "nothing"
                raise KeyError(f"{_fmt(path[:i + 1])}: no such key ({where} has: {has})")
        if last:
            node[key] = value
        else:
            node = node[key]


# ---------------------------------------------------------------------------------- model
@dataclass(frozen=True)
class Point:
    """One simulation of the sweep: its index, parameter values (key path -> value) and seed."""

    index: int
    params: dict[str, Any]
    seed: int


@dataclass
class Sweep:
    """A validated sweep (after --quick was applied, when asked)."""

    name: str
    scene: dict[str, Any]  # the base scene mapping with `set` applied
    scene_path: str | None  # the scene file, when it is one
    kind: str  # "grid" | "random"
    axes: dict[str, list[Any]]  # grid: key path -> values; random: key path -> [distribution, args]
    run: dict[str, Any]
    measures: tuple[str, ...]
    verdicts: list[dict[str, Any]]
    theory: dict[str, Any] | None
    map: dict[str, Any]
    batch: int | None
    seed: int
    draws: int = 0
    quick: bool = False
    path: str | None = None
    points: list[Point] = field(default_factory=list)

    @property
    def params(self) -> list[str]:
        return list(self.axes)

    def fingerprint(self) -> dict[str, Any]:
        """What identifies the results (a resumed sweep must have the same): all but batch size."""
        return {"name": self.name, "scene": self.scene, "kind": self.kind, "axes": self.axes, "run": self.run,
                "measures": list(self.measures), "verdicts": self.verdicts, "theory": self.theory,
                "seed": self.seed, "draws": self.draws, "quick": self.quick}

    def digest(self) -> str:
        text = json.dumps(self.fingerprint(), sort_keys=True, default=repr)
        return hashlib.sha256(text.encode()).hexdigest()[:16]

    def point_scene(self, point: Point) -> tuple[dict[str, Any], dict[str, Any]]:
        """(scene mapping, run options) of one point."""
        scene, run = copy.deepcopy(self.scene), dict(self.run)
        for key, value in point.params.items():
            path = parse_path(key)
            if path[0] == "run":
                run[path[1]] = value
            else:
                set_path(scene, path, value)
        return scene, run


# ------------------------------------------------------------------------------- loading
def _number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def _axis_values(where: str, spec: Any, errors: list[str]) -> list[Any] | None:
    """The values of one grid axis."""
    if isinstance(spec, list):
        spec = {"values": spec}
    if not isinstance(spec, dict) or len(spec) != 1:
        errors.append(f"{where}: give a list of values, or one of values: [...], linspace: [a, b, n], "
                      "logspace: [a, b, n]")
        return None
    (kind, args), = spec.items()
    if kind == "values":
        if not isinstance(args, list) or not args:
            errors.append(f"{where}.values: a non-empty list")
            return None
        if len(args) > MAX_GRID_VALUES:
            errors.append(f"{where}.values: at most {MAX_GRID_VALUES} values")
            return None
        for i, v in enumerate(args):
            if not (_number(v) or isinstance(v, str)):
                errors.append(f"{where}.values[{i}]: a finite number or a string, not {v!r}")
                return None
        if len(set(map(repr, args))) != len(args):
            errors.append(f"{where}.values: repeated values")
            return None
        return list(args)
    if kind in ("linspace", "logspace"):
        if not (isinstance(args, list) and len(args) == 3 and _number(args[0]) and _number(args[1])
                and isinstance(args[2], int) and not isinstance(args[2], bool)):
            errors.append(f"{where}.{kind}: [start, stop, count] with numbers and an integer count")
            return None
        a, b, n = float(args[0]), float(args[1]), args[2]
        if not 1 <= n <= MAX_GRID_VALUES:
            errors.append(f"{where}.{kind}: count must be in 1..{MAX_GRID_VALUES}")
            return None
        if n > 1 and a == b:
            errors.append(f"{where}.{kind}: start == stop with {n} values")
            return None
        if kind == "logspace":
            if a <= 0 or b <= 0:
                errors.append(f"{where}.logspace: start and stop must be > 0 (the values themselves, not exponents)")
                return None
            return [float(x) for x in np.geomspace(a, b, n)]
        return [float(x) for x in np.linspace(a, b, n)]
    errors.append(f"{where}: unknown {kind!r} (values | linspace | logspace)")
    return None


def _distribution(where: str, spec: Any, errors: list[str]) -> list[Any] | None:
    if not isinstance(spec, dict) or len(spec) != 1:
        errors.append(f"{where}: one of {', '.join(f'{d}: [...]' for d in DISTRIBUTIONS)}")
        return None
    (kind, args), = spec.items()
    if kind not in DISTRIBUTIONS:
        errors.append(f"{where}: unknown distribution {kind!r} ({' | '.join(DISTRIBUTIONS)})")
        return None
    if kind == "choice":
        if not isinstance(args, list) or not args or not all(_number(v) or isinstance(v, str) for v in args):
            errors.append(f"{where}.choice: a non-empty list of numbers or strings")
            return None
        return [kind, list(args)]
    if not (isinstance(args, list) and len(args) == 2 and all(_number(v) for v in args)):
        errors.append(f"{where}.{kind}: two finite numbers")
        return None
    a, b = float(args[0]), float(args[1])
    if kind in ("uniform", "loguniform") and not a < b:
        errors.append(f"{where}.{kind}: [low, high] with low < high")
        return None
    if kind == "loguniform" and a <= 0:
        errors.append(f"{where}.loguniform: low must be > 0")
        return None
    if kind == "normal" and not b > 0:
        errors.append(f"{where}.normal: [mean, std] with std > 0")
        return None
    return [kind, [a, b]]


def point_seed(seed: int, index: int) -> np.random.SeedSequence:
    """The seed sequence of point `index` (what SeedSequence(seed).spawn gives as child `index`)."""
    return np.random.SeedSequence(seed, spawn_key=(index,))


def _seed_value(ss: np.random.SeedSequence) -> int:
    """A 63-bit integer for the table's `seed` column (the first word of the sequence's state)."""
    return int(ss.generate_state(1, np.uint64)[0] >> np.uint64(1))


def _draw(rng: np.random.Generator, dist: list[Any]) -> Any:
    kind, args = dist
    if kind == "uniform":
        return float(rng.uniform(args[0], args[1]))
    if kind == "loguniform":
        return float(np.exp(rng.uniform(math.log(args[0]), math.log(args[1]))))
    if kind == "normal":
        return float(rng.normal(args[0], args[1]))
    value = args[int(rng.integers(len(args)))]
    return value


def make_points(sweep: Sweep) -> list[Point]:
    """Every point, in index order (grid: the first key varies slowest)."""
    if sweep.kind == "grid":
        keys = list(sweep.axes)
        combos = itertools.product(*(sweep.axes[k] for k in keys))
        return [Point(i, dict(zip(keys, c)), _seed_value(point_seed(sweep.seed, i))) for i, c in enumerate(combos)]
    out = []
    for i in range(sweep.draws):
        ss = point_seed(sweep.seed, i)
        rng = np.random.default_rng(ss)
        out.append(Point(i, {k: _draw(rng, d) for k, d in sweep.axes.items()}, _seed_value(ss)))
    return out


def _merge_quick(data: dict[str, Any], quick: Any, errors: list[str]) -> dict[str, Any]:
    if not isinstance(quick, dict):
        errors.append("quick: a mapping (grid, random, run, set, ...) whose entries replace the file's")
        return data
    out = copy.deepcopy(data)
    for key, value in quick.items():
        if key not in TOP_KEYS or key == "quick":
            errors.append(f"quick.{key}: unknown key")
        elif isinstance(value, dict) and isinstance(out.get(key), dict):
            merged = dict(out[key])
            merged.update(value)
            out[key] = merged
        else:
            out[key] = value
    return out


def _resolve_scene(source: Any, base_dir: Path | None, errors: list[str]):
    """(scene mapping, path or None) of `scene:`."""
    from gyro_sim.paths import find_scene

    if isinstance(source, dict):
        return copy.deepcopy(source), None
    if not isinstance(source, str) or not source.strip():
        errors.append("scene: the name of a shipped scene, a path (a scene, or an MJCF or URDF model), "
                      "or a scene mapping")
        return None, None
    candidates = []
    if base_dir is not None and not os.path.isabs(source):
        candidates.append(base_dir / source)
    for c in candidates:
        if c.is_file():
            path = c
            break
    else:
        try:
            path = find_scene(source)
        except FileNotFoundError as exc:
            errors.append(f"scene: {exc}")
            return None, None
    from gyro_sim.scene.mjcf import ModelError, import_model, is_model_path

    if is_model_path(path):  # an MJCF or URDF model: its scene mapping (the model's first keyframe)
        try:
            return import_model(path).mapping, str(path)
        except ModelError as exc:
            errors.append(f"scene: {exc}".splitlines()[0])
            return None, None
    try:
        with open(path, encoding="utf-8") as f:
            data = yaml.safe_load(f)
    except (OSError, yaml.YAMLError) as exc:
        errors.append(f"scene: {path}: {exc}".splitlines()[0])
        return None, None
    if not isinstance(data, dict):
        errors.append(f"scene: {path}: not a scene mapping")
        return None, None
    return data, str(path)


def load_sweep(source: str | os.PathLike | Mapping, *, quick: bool = False, validate_points: bool = True) -> Sweep:
    """Load and validate a sweep (a YAML path or a mapping); with `quick`, the file's `quick:`
    entries replace its own. Every point's scene is loaded (validated) unless `validate_points`
    is False. Raises SweepError listing every problem, each naming its key path."""
    path = None
    base_dir = None
    if isinstance(source, Mapping):
        data: Any = copy.deepcopy(dict(source))
    else:
        path = os.fspath(source)
        p = Path(path)
        if not p.is_file():
            raise SweepError([f"{path}: no such file" if not p.exists() else f"{path}: not a file"], path)
        if p.stat().st_size > MAX_FILE_BYTES:
            raise SweepError([f"{path}: larger than {MAX_FILE_BYTES} bytes"], path)
        base_dir = p.resolve().parent
        try:
            with open(p, encoding="utf-8") as f:
                data = yaml.safe_load(f)
        except (OSError, UnicodeDecodeError, yaml.YAMLError) as exc:
            text = " ".join(str(exc).split())
            if "flow" in text and "'['" in text:
                text += ' (inside { } quote key paths with [ ]: {"bodies[0].com[2]": ...})'
            raise SweepError([text], path) from None
    if not isinstance(data, dict):
        raise SweepError(["the file must be a mapping (name, scene, grid or random, run, ...)"], path)
    errors: list[str] = []
    for key in data:
        if key not in TOP_KEYS:
            errors.append(f"{key}: unknown key (known: {', '.join(TOP_KEYS)})")
    if quick and "quick" in data:
        data = _merge_quick(data, data["quick"], errors)
    name = data.get("name", Path(path).stem if path else "sweep")
    if not isinstance(name, str) or not name.strip() or len(name) > 200:
        errors.append("name: a non-empty string of at most 200 characters")
        name = "sweep"
    if "scene" not in data:
        errors.append("scene: missing (a shipped scene name, a path or a mapping)")
        scene, scene_path = None, None
    else:
        scene, scene_path = _resolve_scene(data["scene"], base_dir, errors)

    # --- set: fixed edits
    sets = data.get("set", {}) or {}
    if not isinstance(sets, dict):
        errors.append("set: a mapping of key path -> value")
        sets = {}
    if scene is not None:
        for key, value in sets.items():
            try:
                kp = parse_path(key)
                if kp[0] == "run":
                    raise KeyError("run options go in run:, not set:")
                set_path(scene, kp, value)
            except (ValueError, KeyError) as exc:
                errors.append(f"set[{key}]: {exc.args[0]}")

    # --- run
    run = dict(RUN_DEFAULTS)
    run_in = data.get("run", {}) or {}
    if not isinstance(run_in, dict):
        errors.append("run: a mapping (integrator, rtol, atol, step, horizon, chunk, backend)")
        run_in = {}
    for key, value in run_in.items():
        if key not in RUN_DEFAULTS:
            errors.append(f"run.{key}: unknown key (known: {', '.join(RUN_DEFAULTS)})")
        else:
            run[key] = value
    errors += [f"run.{e}" for e in check_run(run)]

    # --- grid or random
    kind, axes, draws = "grid", {}, 0
    seed = data.get("seed", 0)
    if "grid" in data and "random" in data:
        errors.append("grid, random: give one of them, not both")
    elif "grid" in data:
        grid = data["grid"]
        if not isinstance(grid, dict) or not grid:
            errors.append("grid: a mapping of key path -> values")
        else:
            for key, spec in grid.items():
                vals = _axis_values(f"grid[{key}]", spec, errors)
                if vals is not None:
                    axes[str(key)] = vals
    elif "random" in data:
        kind = "random"
        rnd = data["random"]
        if not isinstance(rnd, dict):
            errors.append("random: a mapping with draws, seed, parameters")
        else:
            for key in rnd:
                if key not in ("draws", "seed", "parameters"):
                    errors.append(f"random.{key}: unknown key (draws, seed, parameters)")
            draws = rnd.get("draws")
            if not isinstance(draws, int) or isinstance(draws, bool) or not 1 <= draws <= MAX_POINTS:
                errors.append(f"random.draws: an integer in 1..{MAX_POINTS}")
                draws = 0
            if "seed" not in rnd:
                errors.append("random.seed: missing (the draws must be reproducible)")
            seed = rnd.get("seed", 0)
            params = rnd.get("parameters")
            if not isinstance(params, dict) or not params:
                errors.append("random.parameters: a mapping of key path -> distribution")
            else:
                for key, spec in params.items():
                    dist = _distribution(f"random.parameters[{key}]", spec, errors)
                    if dist is not None:
                        axes[str(key)] = dist
    else:
        errors.append("grid or random: missing (what to vary)")
    if not isinstance(seed, int) or isinstance(seed, bool) or seed < 0:
        errors.append("seed: a non-negative integer")
        seed = 0
    section = "grid" if kind == "grid" else "random.parameters"
    for key in list(axes):
        try:
            kp = parse_path(key)
        except ValueError as exc:
            errors.append(f"{section}[{key}]: {exc}")
            del axes[key]
            continue
        if kp[0] == "run":
            if len(kp) != 2 or kp[1] not in RUN_DEFAULTS:
                errors.append(f"{section}[{key}]: run options are run.<{' | '.join(RUN_DEFAULTS)}>")
                del axes[key]
        elif scene is not None:
            try:
                set_path(copy.deepcopy(scene), kp, 0.0)
            except KeyError as exc:
                errors.append(f"{section}[{key}]: {exc.args[0]}")
                del axes[key]
    if kind == "grid" and axes and math.prod(len(v) for v in axes.values()) > MAX_POINTS:
        errors.append(f"grid: {math.prod(len(v) for v in axes.values())} points, more than {MAX_POINTS}")

    # --- measures and verdicts
    measures = data.get("measures", list(DEFAULT_MEASURES))
    if not isinstance(measures, list) or not measures:
        errors.append(f"measures: a non-empty list of {', '.join(MEASURES)}")
        measures = list(DEFAULT_MEASURES)
    for i, m in enumerate(measures):
        if m not in MEASURES:
            errors.append(f"measures[{i}]: unknown measure {m!r} (known: {', '.join(MEASURES)})")
    measures = tuple(m for m in measures if m in MEASURES)
    verdicts = []
    vin = data.get("verdicts", []) or []
    if not isinstance(vin, list):
        errors.append("verdicts: a list of {name, measure, below}")
        vin = []
    for i, v in enumerate(vin):
        where = f"verdicts[{i}]"
        if not isinstance(v, dict):
            errors.append(f"{where}: a mapping {{name, measure, below}}")
            continue
        for key in v:
            if key not in ("name", "measure", "below"):
                errors.append(f"{where}.{key}: unknown key (name, measure, below)")
        vname, meas, below = v.get("name"), v.get("measure"), v.get("below")
        if not isinstance(vname, str) or not re.fullmatch(r"[a-z][a-z0-9_]{0,40}", vname or ""):
            errors.append(f"{where}.name: a lower-case identifier (stays_up, stable, ...)")
        elif any(vname == w["name"] for w in verdicts):
            errors.append(f"{where}.name: {vname!r} given twice")
        if meas not in VERDICT_MEASURES:
            errors.append(f"{where}.measure: one of {', '.join(VERDICT_MEASURES)}")
        elif VERDICT_MEASURES[meas] not in measures:
            errors.append(f"{where}.measure: {meas} needs {VERDICT_MEASURES[meas]!r} in measures")
        if not _number(below) or below <= 0:
            errors.append(f"{where}.below: a positive number (the verdict holds while the measure stays below it)")
        verdicts.append({"name": vname, "measure": meas, "below": float(below) if _number(below) else 0.0})
    vnames = [v["name"] for v in verdicts]

    # --- theory, map, batch
    from gyro_sim.sweep.theory import FORMULAS

    theory = data.get("theory")
    if theory is not None:
        if not isinstance(theory, dict) or set(theory) - {"formula", "verdict"}:
            errors.append("theory: {formula: <name>, verdict: <one of verdicts>}")
            theory = None
        else:
            if theory.get("formula") not in FORMULAS:
                errors.append(f"theory.formula: one of {', '.join(FORMULAS)}")
            if theory.get("verdict") not in vnames:
                errors.append(f"theory.verdict: one of the verdicts ({', '.join(vnames) or 'none given'})")
            theory = dict(theory)
    mp = data.get("map", {}) or {}
    if not isinstance(mp, dict):
        errors.append("map: a mapping {kind, x, y, group, verdict}")
        mp = {}
    for key in mp:
        if key not in ("kind", "x", "y", "group", "verdict"):
            errors.append(f"map.{key}: unknown key (kind, x, y, group, verdict)")
    default_kind = "heatmap" if kind == "grid" and len(axes) >= 2 else "histogram"
    mp = {"kind": mp.get("kind", default_kind), "x": mp.get("x"), "y": mp.get("y"), "group": mp.get("group"),
          "verdict": mp.get("verdict", vnames[0] if vnames else None)}
    if mp["kind"] not in MAP_KINDS:
        errors.append(f"map.kind: one of {', '.join(MAP_KINDS)}")
    if mp["kind"] in ("heatmap", "largest"):
        keys = list(axes)
        if kind != "grid":
            errors.append(f"map.kind: {mp['kind']} needs a grid")
        else:
            mp["x"] = mp["x"] or (keys[1] if len(keys) > 1 else None)
            mp["y"] = mp["y"] or (keys[0] if keys else None)
            for k in ("x", "y", "group"):
                if mp[k] is not None and mp[k] not in axes:
                    errors.append(f"map.{k}: {mp[k]!r} is not a grid key ({', '.join(keys)})")
            if mp["x"] is None or mp["y"] is None or mp["x"] == mp["y"]:
                errors.append(f"map: a {mp['kind']} needs two different grid keys x and y")
    if mp["verdict"] is not None and mp["verdict"] not in vnames:
        errors.append(f"map.verdict: one of the verdicts ({', '.join(vnames) or 'none given'})")
    batch = data.get("batch")
    if batch is not None and (not isinstance(batch, int) or isinstance(batch, bool) or not 1 <= batch <= 10_000):
        errors.append("batch: an integer in 1..10000 (points per task)")
        batch = None
    if errors:
        raise SweepError(errors, path)

    sweep = Sweep(name=name, scene=scene, scene_path=scene_path, kind=kind, axes=axes, run=run,
                  measures=measures, verdicts=verdicts, theory=theory, map=mp, batch=batch, seed=seed,
                  draws=draws, quick=quick, path=path)
    sweep.points = make_points(sweep)
    if validate_points:
        errors = check_points(sweep)
        if errors:
            raise SweepError(errors, path)
    return sweep


def check_run(run: Mapping[str, Any]) -> list[str]:
    """Problems with run options, each as ``<key>: <rule>``."""
    from gyro_sim.integrators import INTEGRATORS

    errors = []
    if run.get("integrator") not in INTEGRATORS:
        errors.append(f"integrator: {run.get('integrator')!r} is not one of {', '.join(INTEGRATORS)}")
    if run.get("backend") not in ("auto", "numba", "numpy"):
        errors.append("backend: auto | numba | numpy")
    for key in RUN_FLOATS:
        v = run.get(key)
        if not _number(v) or v <= 0:
            errors.append(f"{key}: a positive number, not {v!r}")
    if not errors:
        if run["chunk"] > run["horizon"]:
            errors.append(f"chunk: {run['chunk']:g} s is longer than the horizon {run['horizon']:g} s")
        elif run["horizon"] / run["chunk"] > 1e7:
            errors.append("chunk: more than 1e7 chunks in the horizon")
        if run["horizon"] / run["step"] > 1e8 and run["integrator"] in ("rk4", "lie4"):
            errors.append("step: more than 1e8 steps in the horizon")
    return errors


def check_points(sweep: Sweep) -> list[str]:
    """Load every point's scene and check its run options; the first few problems, each naming
    the point, its parameter values and the key."""
    from gyro_sim.scene.load import SceneError, load_scene

    errors: list[str] = []
    seen: dict[str, str | None] = {}
    for point in sweep.points:
        scene, run = sweep.point_scene(point)
        problems = [f"run.{e}" for e in check_run(run)]
        key = json.dumps(scene, sort_keys=True, default=repr)
        if key not in seen:
            try:
                load_scene(scene)
                seen[key] = None
            except SceneError as exc:
                seen[key] = "; ".join(exc.errors)
        if seen[key]:
            problems.append(seen[key])
        if problems:
            vals = ", ".join(f"{k} = {v!r}" for k, v in point.params.items())
            errors.append(f"point {point.index} ({vals}): " + "; ".join(problems))
            if len(errors) >= 5:
                errors.append("(and maybe more points; the first 5 shown)")
                break
    return errors
