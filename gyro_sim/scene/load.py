"""Scene loader: a YAML file or a mapping -> a validated, immutable :class:`Scene`.

The contract is docs/scene-format.md. `load_scene` checks everything before it builds a
record, collects every problem it finds and raises one :class:`SceneError` listing them, one
per line, each as ``<key path>: <rule>`` (``bodies[1].inertia_com: not positive definite``).
Nothing downstream ever sees a bad scene.

Conventions fixed here (beyond the SPEC's example file):

- an explicit ``null`` counts as an absent key (so ``rotors:`` with nothing under it is no
  rotors), except that a required key must hold a value;
- YAML is read with a safe loader that refuses duplicate keys and reads ``1e-6`` as a float
  (plain YAML 1.1 reads it as a string);
- inertia tensors must be those of a real mass distribution: symmetric, positive definite,
  principal moments obeying the triangle inequality, both about O^k and about the centre of
  mass (docs/theory.md section 6: about the centre of mass the transverse moment is B - m c^2);
- names are kept as given (printable, no whitespace or ``/``, at most ``MAX_NAME_LENGTH``
  characters: gyro_sim.scene.names), unique over bodies and rotors, and so are the joint-state
  names they produce and the topic tokens of the bodies' and IMUs' topics (``<body>_psi`` ... for spherical joints,
  docs/scene-format.md);
- crafted input is bounded: only a regular file is read (a FIFO, ``/dev/zero`` or another
  device is refused before anything is read from it), of at most ``MAX_SCENE_BYTES``; its
  YAML at most ``MAX_YAML_DEPTH`` levels deep (aliases expanded) and at most
  ``MAX_YAML_ALIAS_NODES`` nodes reached through aliases (a "billion laughs" is refused
  before any object is built); every number finite and within the physical sanity bound of
  its key (``BOUNDS``, stated in the error). A long scene is not hostile: the nodes written
  out in the file are bounded by its size alone (a 5000-body chain is about 2 MB).
"""
from __future__ import annotations

import copy
import dataclasses
import difflib
import gc
import math
import numbers
import os
import re
import stat
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import yaml

from gyro_sim.errors import GyroSimError
from gyro_sim.scene.mjcf import ModelError, import_model, is_model_path
from gyro_sim.scene.names import name_problem, topic_token
from gyro_sim.scene.records import (
    BASE_TYPES, JOINT_TYPES, ONE_AXIS_JOINTS, ROTOR_MODES, Base, Body, Friction, Imu, Initial, Joint,
    Limits, Motor, Rotor, Scene, Servo, Spring,
)

__all__ = ["SceneError", "load_scene", "parse_yaml"]

#: relative tolerance of the triangle inequality of principal moments (I1 + I2 >= I3)
TRIANGLE_RTOL = 1e-9
#: relative tolerance of the symmetry of a written inertia tensor
SYMMETRY_RTOL = 1e-9
#: smallest principal moment, relative to the largest, of a positive definite inertia
PD_RTOL = 1e-12
#: joint-state suffixes of a spherical joint's Euler angles (docs/scene-format.md)
EULER_SUFFIXES = ("psi", "theta", "phi")
MOTION_TYPES = ("sine",)
#: deepest nesting of a scene file, aliases expanded (a scene needs 6 levels)
MAX_YAML_DEPTH = 32
#: most nodes reached through aliases, counted expanded (what an alias costs once the data is
#: walked); the nodes written out in the file are bounded by MAX_SCENE_BYTES instead
MAX_YAML_ALIAS_NODES = 1_000_000
#: largest scene file (or embedded scene text) read, in bytes: 30 times a 5000-body chain
MAX_SCENE_BYTES = 64 * 1024 * 1024
#: physical sanity bounds on magnitudes, by key: (largest |value|, unit). Far beyond any chain
#: the simulator is meant for, and far below where products of them overflow.
BOUNDS = {
    "mass": (1e9, "kg"),
    "axial": (1e12, "kg m^2"), "transverse": (1e12, "kg m^2"), "inertia_com": (1e12, "kg m^2"),
    "axial_inertia": (1e12, "kg m^2"), "transverse_inertia": (1e12, "kg m^2"),
    "com": (1e4, "m"), "next_joint": (1e4, "m"), "at": (1e4, "m"), "position": (1e4, "m"), "radius": (1e4, "m"),
    "amplitude": (1e3, "m"), "gravity": (1e4, "m/s^2"), "frequency": (1e6, "Hz"),
    "velocity": (1e6, "m/s"),
    "spin": (1e7, "rad/s"), "rate": (1e7, "rad/s"), "euler_rates": (1e7, "rad/s"),
    "angular_velocity": (1e7, "rad/s"),
    "euler": (1e6, "rad"), "angle": (1e6, "rad"),
    "gyro_noise_density": (1e3, "rad/s/sqrt(Hz)"), "gyro_bias_instability": (1e3, "rad/s^2/sqrt(Hz)"),
    "accel_noise_density": (1e4, "m/s^2/sqrt(Hz)"), "accel_bias_instability": (1e4, "m/s^3/sqrt(Hz)"),
    "max_torque": (1e9, "N m"), "max_speed": (1e7, "rad/s"), "coulomb": (1e9, "N m"),
    "viscous": (1e9, "N m s/rad"), "static": (1e9, "N m"), "stribeck_speed": (1e7, "rad/s"),
    "stick_speed": (1e7, "rad/s"),
    "armature": (1e12, "kg m^2"), "stiffness": (1e12, "N m/rad"), "reference": (1e6, "rad"),
}
#: bound of any other number (unit vectors before normalisation, quaternions)
GENERIC_BOUND = 1e15

TOP_KEYS = ("name", "gravity", "base", "bodies", "imus")
BASE_KEYS = ("type", "position", "motion", "velocity")
BASE_TYPE_KEYS = {"fixed": ("type", "position"), "moving": ("type", "position", "motion"),
                  "free": ("type", "position", "velocity")}
MOTION_KEYS = ("type", "amplitude", "frequency")
BODY_KEYS = ("name", "parent", "joint", "mass", "com", "inertia", "inertia_com", "next_joint", "rotors",
             "initial", "visual")
#: a body's `parent` naming the base: the body hangs from the base (docs/scene-format.md)
BASE_PARENT = "base"
JOINT_KEYS = ("type", "axis", "at", "max_torque", "friction", "armature", "spring", "servo", "motor")
#: a hinge's terms a spherical joint does not take (docs/scene-format.md)
HINGE_ONLY_KEYS = ("armature", "spring", "servo", "motor")
MOTOR_KEYS = ("inertia", "gear", "axis")
SPRING_KEYS = ("stiffness", "reference")
SERVO_KEYS = ("name", "gain", "bias", "gear", "ctrl_range", "force_range", "control")
#: a hinge's limits (JOINT_KEYS) and a torque rotor's (ROTOR_KEYS)
HINGE_LIMIT_KEYS = ("max_torque", "friction")
ROTOR_LIMIT_KEYS = ("max_torque", "max_speed", "friction")
FRICTION_KEYS = ("coulomb", "viscous", "static", "stribeck_speed", "stick_speed")
INERTIA_KEYS = ("axial", "transverse")
VISUAL_KEYS = ("radius",)
ROTOR_KEYS = ("name", "axis", "position", "mass", "axial_inertia", "transverse_inertia", "mode",
              "spin", "actuated") + ROTOR_LIMIT_KEYS
EULER_KEYS = ("euler", "euler_rates")
QUATERNION_KEYS = ("quaternion", "angular_velocity")
HINGE_INITIAL_KEYS = ("angle", "rate")
SLIDE_INITIAL_KEYS = ("position", "velocity")
INITIAL_KEYS = EULER_KEYS + QUATERNION_KEYS + HINGE_INITIAL_KEYS + SLIDE_INITIAL_KEYS
IMU_NOISE_KEYS = ("gyro_noise_density", "gyro_bias_instability", "accel_noise_density",
                  "accel_bias_instability")
IMU_KEYS = ("name", "body", "position", "orientation", "rate", "seed") + IMU_NOISE_KEYS
#: largest seed of an IMU's random generator (numpy's PCG64 takes any non-negative integer;
#: 64 bits keep it exact in every log's YAML and JSON)
MAX_IMU_SEED = 2**64 - 1

_REQUIRED = object()  # default marker: the key must be given


class SceneError(GyroSimError, ValueError):
    """A scene that cannot be loaded. `errors` lists every problem as ``<key path>: <rule>``."""

    def __init__(self, errors: Sequence[str], path: str | None = None):
        self.errors = list(errors)
        self.path = path
        where = f"invalid scene {path!r}" if path is not None else "invalid scene"
        if len(self.errors) == 1:  # one problem, one line
            super().__init__(f"{where}: {self.errors[0]}")
            return
        count = f"{len(self.errors)} errors"
        super().__init__(f"{where} ({count}):\n" + "\n".join("  " + e for e in self.errors))


def load_scene(source: str | os.PathLike | Mapping, keyframe: str | None = None,
               package_path: Sequence[str | os.PathLike] = (),
               lock: Mapping[str, float | None] | Sequence[str] = (),
               balance_inertia: bool = False, geared_motors: float | None = None) -> Scene:
    """Load and validate a scene.

    Parameters
    ----------
    source : str, os.PathLike or Mapping
        A path to a YAML scene file, the name of a shipped scene (``"hinge_chain"``, found in
        the installed package's config/ wherever the caller stands; see
        :func:`gyro_sim.paths.find_scene`), or a mapping with the same keys (vectors as
        sequences or numpy arrays). A path ending in ``.xml``, ``.mjcf`` or ``.urdf`` is an
        MJCF or URDF model, read through MuJoCo (:mod:`gyro_sim.scene.mjcf`, docs/models.md).
    keyframe : str, optional
        Models only: the keyframe giving the initial state (default: the model's first, or
        the reference pose at rest; ``"none"``: the reference pose at rest).
    package_path : sequence of directories, optional
        Models only: searched first for the packages of ``package://`` mesh URIs, before the
        ament index, ROS_PACKAGE_PATH and the package.xml above the file
        (:mod:`gyro_sim.scene.packages`).
    lock : mapping or sequence, optional
        Models only: joints welded where they are, their bodies merged into their parents: a
        mapping joint name -> value (rad or m; None: the keyframe's value, else the reference
        position), or ``"NAME"`` / ``"NAME=VALUE"`` strings (docs/models.md, "Locked joints").
    balance_inertia : bool, optional
        Models only: a moving body's inertia outside the triangle inequality takes MuJoCo's
        balanced one (docs/models.md, "Inertias outside the triangle inequality") instead of
        being refused.
    geared_motors : float, optional
        Models only: every hinge's armature a becomes the geared motor of this gear ratio G it
        reflects (a rotor of axial inertia a / G^2 on the parent: docs/models.md, "The geared
        motor against the armature").

    Returns
    -------
    Scene
        The validated scene: vectors as read-only float arrays, unit axes normalised, inertia
        tensors about O^k; `source` is a plain deep copy of the mapping, `path` the file path
        (None for a mapping).

    Raises
    ------
    SceneError
        Listing every problem found (also for a missing file or a YAML syntax error).
    """
    path = model = None
    if isinstance(source, Mapping):
        data: Any = source
    elif isinstance(source, (str, os.PathLike)):
        path = os.fspath(source)
        if not os.path.exists(path) and os.path.basename(path) == path:
            from gyro_sim.paths import find_scene

            try:  # a bare name: a shipped scene (a path with a directory part stays a path)
                path = os.fspath(find_scene(path))
            except FileNotFoundError as exc:
                raise SceneError([str(exc)], path) from None
        if is_model_path(path):  # MJCF or URDF: its scene mapping, refusals naming elements
            try:
                model = import_model(path, keyframe, package_path=package_path, lock=lock,
                                     balance_inertia=balance_inertia, geared_motors=geared_motors)
            except ModelError as exc:
                raise SceneError(exc.errors, path) from None
            data = model.mapping
        else:
            data = _read_yaml(path)
    else:
        raise SceneError([f"scene: must be a file path or a mapping (got {_describe(source)})"])
    if balance_inertia and model is None:
        raise SceneError(["balance_inertia: only an MJCF or URDF model's inertias are balanced (a "
                          "scene file's inertia must obey the triangle inequality)"], path)
    if geared_motors is not None and model is None:
        raise SceneError(["geared_motors: only an MJCF model's armatures become geared motors (a "
                          "scene file gives a hinge its `motor`)"], path)
    if lock and model is None:
        raise SceneError(["lock: only the joints of an MJCF or URDF model are locked (a scene "
                          "file's chain is written as it moves)"], path)
    if keyframe is not None and model is None:
        raise SceneError([f"keyframe: only an MJCF or URDF model has keyframes (got {keyframe!r})"],
                         path)
    checker = _Checker()
    scene = _scene(checker, data)
    if not checker.errors and any(b.mass == 0.0 for b in scene.bodies):
        checker.errors += _massless_problems(scene)
    if checker.errors:
        raise SceneError(checker.errors if model is None else model.describe(checker.errors), path)
    return dataclasses.replace(scene, source=_plain(data), path=path,
                               robot=None if model is None else model.robot)


# ---------------------------------------------------------------------------------------------
# YAML


#: libyaml's parser when PyYAML was built with it (about 5 times faster), else PyYAML's own
_SafeLoaderBase = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


class _SceneYamlLoader(_SafeLoaderBase):
    """Safe loader that refuses duplicate keys and reads ``1e-6`` as a float."""

    def construct_mapping(self, node, deep=False):
        seen = set()
        for key_node, _ in node.value:
            if key_node.tag == "tag:yaml.org,2002:merge":
                continue
            key = self.construct_object(key_node, deep=True)
            try:
                duplicate = key in seen
            except TypeError:  # unhashable key: the base class reports it
                continue
            if duplicate:
                raise yaml.constructor.ConstructorError(
                    "while reading a mapping", node.start_mark,
                    f"found duplicate key {key!r}", key_node.start_mark)
            seen.add(key)
        return super().construct_mapping(node, deep=deep)


_SceneYamlLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?[0-9][0-9_]*(?:\.[0-9_]*)?[eE][-+]?[0-9]+$"),
    list("-+0123456789"),
)


def _yaml_bounds_problem(text: str) -> str | None:
    """Why `text` is too deep or expands too much through aliases to load, or None.

    Walks the parser's events (the parser is iterative; the composer that builds objects is
    recursive and would raise RecursionError on deep nesting). Each anchor's size and depth
    are kept once its node ends, so an alias costs one addition however large its node: a
    "billion laughs" is refused after a few hundred events."""
    stack: list[list] = []  # open collections: [anchor, nodes so far, deepest below]
    sizes: dict[str, tuple[int, int]] = {}  # anchor -> (nodes, depth), aliases inside expanded
    via_aliases = 0
    for event in yaml.parse(text, Loader=_SceneYamlLoader):
        if isinstance(event, (yaml.MappingStartEvent, yaml.SequenceStartEvent)):
            stack.append([event.anchor, 0, 0])
            if len(stack) > MAX_YAML_DEPTH:
                return (f"YAML nested deeper than {MAX_YAML_DEPTH} levels (line "
                        f"{event.start_mark.line + 1}); a scene needs about 6")
            continue
        if isinstance(event, (yaml.MappingEndEvent, yaml.SequenceEndEvent)):
            anchor, nodes, below = stack.pop()
            nodes, depth = nodes + 1, below + 1
        elif isinstance(event, yaml.ScalarEvent):
            anchor, nodes, depth = event.anchor, 1, 0
        elif isinstance(event, yaml.AliasEvent):
            if event.anchor not in sizes:
                return f"YAML alias *{event.anchor} refers to its own node or an unknown anchor"
            anchor = None
            nodes, depth = sizes[event.anchor]
            via_aliases += nodes
            if via_aliases > MAX_YAML_ALIAS_NODES:
                return (f"YAML aliases expand to more than {MAX_YAML_ALIAS_NODES} nodes (line "
                        f"{event.start_mark.line + 1}): refused as an alias bomb")
        else:
            continue
        if anchor is not None:
            sizes[anchor] = (nodes, depth)
        if stack:
            stack[-1][1] += nodes
            stack[-1][2] = max(stack[-1][2], depth)
            if len(stack) + depth > MAX_YAML_DEPTH:
                return f"YAML nested deeper than {MAX_YAML_DEPTH} levels (aliases expanded)"
    return None


def _load_without_gc(text: str) -> Any:
    """``yaml.load`` with the cyclic garbage collector paused: the objects built are all kept,
    and collecting while they pile up makes the time grow faster than the scene (a 5000-body
    chain loads about 2.5 times faster without it)."""
    enabled = gc.isenabled()
    gc.disable()
    try:
        return yaml.load(text, Loader=_SceneYamlLoader)  # a SafeLoader
    finally:
        if enabled:
            gc.enable()


def parse_yaml(text: str, where: str = "scene") -> Any:
    """YAML text -> plain data with the scene loader (safe, no duplicate keys, size, depth and
    alias expansion bounded); SceneError naming `where` otherwise."""
    if len(text) > MAX_SCENE_BYTES:  # characters: at least as many bytes
        raise SceneError([f"{where}: larger than {MAX_SCENE_BYTES} bytes"], where)
    try:
        problem = _yaml_bounds_problem(text)
        if problem is not None:
            raise SceneError([f"{where}: {problem}"], where)
        return _load_without_gc(text)
    except yaml.YAMLError as exc:
        if "nesting depth" in str(getattr(exc, "problem", "")):  # libyaml's own bound (1000 levels)
            raise SceneError([f"{where}: YAML nested deeper than {MAX_YAML_DEPTH} levels ("
                              f"{_yaml_message(exc)})"], where) from None
        raise SceneError([f"{where}: {_yaml_message(exc)}"], where) from None
    except RecursionError:  # a guard: the bounds above keep the composer well inside the limit
        raise SceneError([f"{where}: YAML nested too deeply"], where) from None


#: what a file that is not a regular file is, by its stat mode
_FILE_KINDS = ((stat.S_ISFIFO, "a FIFO"), (stat.S_ISCHR, "a character device"),
               (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"))


def read_text_file(path: str, limit: int = MAX_SCENE_BYTES) -> str:
    """The UTF-8 text of the regular file `path`, of at most `limit` bytes (SceneError in one
    line otherwise). Opened without blocking (a FIFO with no writer would block ``open``) and
    checked on the open descriptor, so nothing is read from a device or a FIFO."""
    flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0)
    try:
        fd = os.open(path, flags)
    except FileNotFoundError:
        raise SceneError([f"{path}: file not found"], path) from None
    except IsADirectoryError:
        raise SceneError([f"{path}: is a directory, not a scene file"], path) from None
    except OSError as exc:
        raise SceneError([f"{path}: cannot read ({exc.strerror or exc})"], path) from None
    try:
        mode = os.fstat(fd).st_mode
    except OSError:
        os.close(fd)
        raise
    if not stat.S_ISREG(mode):
        os.close(fd)
        if stat.S_ISDIR(mode):
            raise SceneError([f"{path}: is a directory, not a scene file"], path)
        kind = next((name for test, name in _FILE_KINDS if test(mode)), "not a regular file")
        raise SceneError([f"{path}: is {kind}, not a scene file: only regular files are read"], path)
    with os.fdopen(fd, "rb") as stream:
        try:
            data = stream.read(limit + 1)
        except OSError as exc:
            raise SceneError([f"{path}: cannot read ({exc.strerror or exc})"], path) from None
    if len(data) > limit:
        raise SceneError([f"{path}: larger than {limit} bytes: not a scene file"], path)
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise SceneError([f"{path}: not UTF-8 text ({exc.reason} at byte {exc.start})"], path) from None


def _read_yaml(path: str) -> Any:
    return parse_yaml(read_text_file(path), path)


def _yaml_message(exc: yaml.YAMLError) -> str:
    if isinstance(exc, yaml.MarkedYAMLError) and exc.problem_mark is not None:
        mark = exc.problem_mark
        context = f" ({exc.context})" if exc.context else ""
        return (f"YAML error at line {mark.line + 1}, column {mark.column + 1}: "
                f"{exc.problem}{context}")
    return f"YAML error: {exc}"


# ---------------------------------------------------------------------------------------------
# Generic checks: each reports into the checker and returns None on failure


def _describe(value: Any) -> str:
    if value is None:
        return "null"
    if isinstance(value, Mapping):
        return "a mapping"
    if isinstance(value, (list, tuple)):
        return f"a list of {len(value)}"
    text = repr(value)
    if len(text) > 40:
        text = text[:37] + "..."
    return f"{type(value).__name__} {text}"


def _at(path: str, key: Any) -> str:
    token = key if isinstance(key, str) else repr(key)
    return f"{path}.{token}" if path else token


def _readonly(values: Any) -> np.ndarray:
    array = np.array(values, dtype=float)
    array.flags.writeable = False
    return array


def _fmt(values: np.ndarray) -> str:
    return "[" + ", ".join(f"{v:.6g}" for v in values) + "]"


def _plain(value: Any) -> Any:
    """A deep copy made of dicts, lists and Python scalars (numpy values converted)."""
    if isinstance(value, Mapping):
        return {key: _plain(item) for key, item in value.items()}
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, (list, tuple)):
        return [_plain(item) for item in value]
    if isinstance(value, np.generic):
        return value.item()
    return copy.deepcopy(value)


class _Checker:
    """Collects errors; its readers return the checked value, or None after reporting."""

    def __init__(self) -> None:
        self.errors: list[str] = []

    def fail(self, path: str, rule: str) -> None:
        self.errors.append(f"{path}: {rule}")

    def mapping(self, value: Any, path: str, keys: Sequence[str],
                required: Sequence[str] = ()) -> Mapping | None:
        """`value` as a mapping whose keys are all in `keys` and that holds `required`."""
        if not isinstance(value, Mapping):
            self.fail(path or "scene", f"must be a mapping (got {_describe(value)})")
            return None
        for key in value:
            if not isinstance(key, str) or key not in keys:
                hint = ""
                if isinstance(key, str):
                    close = difflib.get_close_matches(key, keys, n=1)
                    hint = f" (did you mean {close[0]!r}?)" if close else ""
                self.fail(_at(path, key), "unknown key" + hint)
        for key in required:
            if key not in value:
                self.fail(_at(path, key), "required key missing")
            elif value[key] is None:
                self.fail(_at(path, key), "required, got null")
        return value

    def number(self, value: Any, path: str, key: str | None = None) -> float | None:
        """A finite real number (bools and strings refused) within the bound of `key` (BOUNDS)."""
        if isinstance(value, (bool, np.bool_)):
            self.fail(path, f"must be a number, not a boolean (got {value})")
            return None
        if not isinstance(value, numbers.Real):
            self.fail(path, f"must be a number (got {_describe(value)})")
            return None
        try:
            result = float(value)
        except OverflowError:
            result = math.inf
        if not math.isfinite(result):
            self.fail(path, f"must be finite (got {result})")
            return None
        limit, unit = BOUNDS.get(key, (GENERIC_BOUND, ""))
        if abs(result) > limit:
            self.fail(path, f"magnitude must be <= {limit:g}{' ' + unit if unit else ''}, the sanity "
                            f"bound of {key or 'a number'} (got {result:g})")
            return None
        return result

    def scalar(self, mapping: Mapping, key: str, path: str, default: Any = _REQUIRED, *,
               minimum: float | None = None, strict: bool = False) -> float | None:
        """A number under `key`, optionally bounded below (> if `strict`, else >=)."""
        value = mapping.get(key)
        if value is None:
            return None if default is _REQUIRED else default  # missing: reported by mapping()
        result = self.number(value, _at(path, key), key)
        if result is None or minimum is None:
            return result
        if result < minimum or (strict and result == minimum):
            self.fail(_at(path, key), f"must be {'>' if strict else '>='} {minimum:g} "
                                      f"(got {result!r})")
            return None
        return result

    def vector(self, mapping: Mapping, key: str, path: str, size: int = 3,
               default: Any = _REQUIRED) -> np.ndarray | None:
        """A list of `size` finite numbers under `key`, as a float array."""
        value = mapping.get(key)
        if value is None:
            return None if default is _REQUIRED else default
        return self.array(value, _at(path, key), size, key)

    def array(self, value: Any, path: str, size: int, key: str | None = None) -> np.ndarray | None:
        if isinstance(value, np.ndarray):
            value = value.tolist() if value.ndim == 1 else value
        if not isinstance(value, (list, tuple)):
            self.fail(path, f"must be a list of {size} numbers (got {_describe(value)})")
            return None
        if len(value) != size:
            self.fail(path, f"must have {size} components (got {len(value)})")
            return None
        items = [self.number(item, f"{path}[{i}]", key) for i, item in enumerate(value)]
        if any(item is None for item in items):
            return None
        return np.array(items, dtype=float)

    def unit(self, mapping: Mapping, key: str, path: str, size: int = 3,
             default: Any = _REQUIRED) -> np.ndarray | None:
        """A non-zero vector under `key`, normalised."""
        value = mapping.get(key)
        if value is None:
            return None if default is _REQUIRED else default
        vector = self.array(value, _at(path, key), size)
        if vector is None:
            return None
        scale = float(np.max(np.abs(vector)))
        if scale == 0.0:
            self.fail(_at(path, key), "zero vector")
            return None
        vector = vector / scale
        return vector / np.linalg.norm(vector)

    def matrix(self, value: Any, path: str, key: str | None = None) -> np.ndarray | None:
        """A 3x3 matrix written as three rows of three numbers."""
        if isinstance(value, np.ndarray):
            value = value.tolist()
        if not isinstance(value, (list, tuple)):
            self.fail(path, f"must be a 3x3 matrix, three rows of three numbers "
                            f"(got {_describe(value)})")
            return None
        if len(value) != 3:
            self.fail(path, f"must have 3 rows (got {len(value)})")
            return None
        rows = [self.array(row, f"{path}[{i}]", 3, key) for i, row in enumerate(value)]
        if any(row is None for row in rows):
            return None
        return np.array(rows)

    def choice(self, mapping: Mapping, key: str, path: str, options: Sequence[str],
               default: Any = _REQUIRED) -> str | None:
        value = mapping.get(key)
        if value is None:
            return None if default is _REQUIRED else default
        if not isinstance(value, str) or value not in options:
            got = repr(value) if isinstance(value, str) else _describe(value)
            self.fail(_at(path, key), f"must be one of {', '.join(options)} (got {got})")
            return None
        return value

    def flag(self, mapping: Mapping, key: str, path: str, default: bool) -> bool | None:
        value = mapping.get(key)
        if value is None:
            return default
        if not isinstance(value, (bool, np.bool_)):
            self.fail(_at(path, key), f"must be true or false (got {_describe(value)})")
            return None
        return bool(value)

    def name(self, mapping: Mapping, key: str, path: str) -> str | None:
        """A name (gyro_sim.scene.names): printable, no whitespace or '/', not too long."""
        value = mapping.get(key)
        if value is None:
            return None
        if not isinstance(value, str):
            self.fail(_at(path, key), f"must be a string (got {_describe(value)})")
            return None
        problem = name_problem(value)
        if problem:
            self.fail(_at(path, key), problem)
            return None
        return value


def _inertia_problem(inertia: np.ndarray) -> str | None:
    """Why a symmetric 3x3 tensor is not the inertia of a mass distribution, or None."""
    moments = np.linalg.eigvalsh(inertia)  # ascending
    if not moments[0] > PD_RTOL * abs(moments[-1]):
        return f"is not positive definite (principal moments {_fmt(moments)})"
    if moments[0] + moments[1] < moments[2] - TRIANGLE_RTOL * float(np.sum(moments)):
        return (f"violates the triangle inequality I1 + I2 >= I3 of principal moments "
                f"({_fmt(moments)})")
    return None


def _point_mass_inertia(mass: float, com: np.ndarray) -> np.ndarray:
    """m (|c|^2 1 - c c^T): the parallel-axis term."""
    return mass * (float(com @ com) * np.eye(3) - np.outer(com, com))


# ---------------------------------------------------------------------------------------------
# The scene, level by level


def _scene(ch: _Checker, data: Any) -> Scene | None:
    top = ch.mapping(data, "", TOP_KEYS, required=("name", "base", "bodies"))
    if top is None:
        return None
    name = top.get("name")
    if name is not None and not isinstance(name, str):
        ch.fail("name", f"must be a string (got {_describe(name)})")
        name = None
    elif isinstance(name, str) and not name.strip():
        ch.fail("name", "must not be empty")
        name = None
    gravity = ch.vector(top, "gravity", "", default=None)
    base = _base(ch, top["base"]) if top.get("base") is not None else None
    base_type = top["base"].get("type") if isinstance(top.get("base"), Mapping) else None
    bodies = _bodies(ch, top.get("bodies"), base_type)
    imus = _imus(ch, top.get("imus"), top.get("bodies"))
    if ch.errors:
        return None
    return Scene(name=name, gravity=None if gravity is None else _readonly(gravity), base=base,
                 bodies=bodies, imus=imus)


def _base(ch: _Checker, value: Any) -> Base | None:
    path = "base"
    base = ch.mapping(value, path, BASE_KEYS, required=("type",))
    if base is None:
        return None
    kind = ch.choice(base, "type", path, BASE_TYPES)
    position = ch.vector(base, "position", path, default=np.zeros(3))
    amplitude = frequency = velocity = None
    if kind is not None:
        for key in base:
            if key in BASE_KEYS and key not in BASE_TYPE_KEYS[kind]:
                owner = "moving" if key == "motion" else "free"
                ch.fail(_at(path, key), f"not allowed for a {kind} base (only a {owner} base "
                                        f"has {key})")
    if kind is None:  # type invalid (already reported): still check the values
        if base.get("motion") is not None:
            _motion(ch, base["motion"], _at(path, "motion"))
        ch.vector(base, "velocity", path, default=None)
    elif kind == "moving":
        if base.get("motion") is None:
            ch.fail(_at(path, "motion"), "required for a moving base "
                                         "({type: sine, amplitude: [x, y, z], frequency: f})")
        else:
            amplitude, frequency = _motion(ch, base["motion"], _at(path, "motion"))
    elif kind == "free":
        velocity = ch.vector(base, "velocity", path, default=np.zeros(3))
    if kind is None or position is None:
        return None
    return Base(type=kind, position=_readonly(position),
                amplitude=None if amplitude is None else _readonly(amplitude),
                frequency=frequency,
                velocity=None if velocity is None else _readonly(velocity))


def _motion(ch: _Checker, value: Any, path: str) -> tuple[np.ndarray | None, float | None]:
    motion = ch.mapping(value, path, MOTION_KEYS, required=MOTION_KEYS)
    if motion is None:
        return None, None
    ch.choice(motion, "type", path, MOTION_TYPES)
    amplitude = ch.vector(motion, "amplitude", path)
    frequency = ch.scalar(motion, "frequency", path, minimum=0.0, strict=True)
    return amplitude, frequency


def _bodies(ch: _Checker, value: Any, base_type: Any) -> tuple[Body, ...] | None:
    if value is None:
        return None  # missing: reported with the top-level keys
    if not isinstance(value, (list, tuple)):
        ch.fail("bodies", f"must be a list of bodies (got {_describe(value)})")
        return None
    if not value:
        ch.fail("bodies", "must not be empty (a scene has at least one body)")
        return None
    names: list[tuple[str, str, str]] = []  # (name, path, joint type or "rotor")
    parents, needs_next = _tree(ch, value, base_type)
    bodies = []
    for index, item in enumerate(value):
        bodies.append(_body(ch, item, f"bodies[{index}]", needs_next[index], names, parents[index],
                            index == len(value) - 1))
    first = value[0]
    first_joint = first.get("joint") if isinstance(first, Mapping) else None
    if base_type == "free" and isinstance(first_joint, Mapping) and \
            first_joint.get("type") in ONE_AXIS_JOINTS:
        ch.fail("bodies[0].joint.type", f"a free base's first joint must be spherical, not a "
                                        f"{first_joint.get('type')}")
    _check_names(ch, names)
    if any(body is None for body in bodies):
        return None
    servos: dict[str, int] = {}
    for index, body in enumerate(bodies):
        servo = body.joint.servo
        if servo is not None and servo.name in servos:
            ch.fail(f"bodies[{index}].joint.servo.name", f"duplicate servo name {servo.name!r} (also "
                                                         f"bodies[{servos[servo.name]}]'s)")
        elif servo is not None:
            servos[servo.name] = index
    return tuple(bodies)


def _tree(ch: _Checker, value: list, base_type: Any) -> tuple[list[int], list[bool | None]]:
    """Each body's parent index (-1: the base) from its `parent` (default: the body before it)
    and, per body, whether a child takes its joint point from the body's `next_joint` (True:
    required), None when the body has no child (refused there), False when every child gives
    `joint.at`."""
    index_of: dict[str, int] = {}
    parents: list[int] = []
    has_at: list[bool] = []
    for index, item in enumerate(value):
        body = item if isinstance(item, Mapping) else {}
        path = f"bodies[{index}]"
        parent = index - 1
        if "parent" in body:
            written = body["parent"]
            if not isinstance(written, str):
                ch.fail(_at(path, "parent"), f"must be a body's name or {BASE_PARENT!r} (got {_describe(written)})")
            elif written == BASE_PARENT:
                parent = -1
            elif written in index_of:
                parent = index_of[written]
            elif any(isinstance(b, Mapping) and b.get("name") == written for b in value[index:]):
                ch.fail(_at(path, "parent"), f"{written!r} is listed at or after this body; a parent "
                                             "comes before its children")
            else:
                ch.fail(_at(path, "parent"), f"unknown body {written!r} (a body listed before this one, "
                                             f"or {BASE_PARENT!r})")
        joint = body.get("joint")
        has_at.append(isinstance(joint, Mapping) and joint.get("at") is not None)
        name = body.get("name")
        if isinstance(name, str) and name != BASE_PARENT:
            index_of.setdefault(name, index)
        elif name == BASE_PARENT:
            ch.fail(_at(path, "name"), f"{BASE_PARENT!r} is reserved: a `parent` naming it is the base")
        parents.append(parent)
    needs_next: list[bool | None] = [None] * len(value)
    for index, parent in enumerate(parents):
        if parent >= 0:
            needs_next[parent] = bool(needs_next[parent]) or not has_at[index]
    on_base = [index for index, parent in enumerate(parents) if parent < 0]
    if base_type == "free" and on_base and has_at[on_base[0]]:
        ch.fail(f"bodies[{on_base[0]}].joint.at", "not allowed on a free base's body (its joint point is "
                                                  "the base's position, the state r0)")
    if base_type == "free" and len(on_base) > 1:
        ch.fail(f"bodies[{on_base[1]}].parent", f"a free base carries one body (bodies[{on_base[0]}] "
                                                "already hangs from it); hang this one from a body")
    return parents, needs_next


def _check_names(ch: _Checker, names: list[tuple[str, str, str]]) -> None:
    """Body and rotor names unique, and so the joint-state names they give."""
    seen: dict[str, str] = {}
    for name, path, _ in names:
        if name in seen:
            ch.fail(path, f"duplicate name {name!r} (also at {seen[name]}); body and rotor "
                          f"names must be unique")
        else:
            seen[name] = path
    tokens: dict[str, tuple[str, str]] = {}
    for name, path, kind in names:
        if kind == "rotor":
            continue  # a body's name makes its wrench topic
        other = tokens.setdefault(topic_token(name), (name, path))
        if other[0] != name:
            ch.fail(path, f"{name!r} and {other[0]!r} (at {other[1]}) make the same topic "
                          f"~/wrench/{topic_token(name)}; rename one")
    states: dict[str, tuple[str, str]] = {}
    for name, path, kind in names:
        outputs = [f"{name}_{s}" for s in EULER_SUFFIXES] if kind == "spherical" else [name]
        for output in outputs:
            other = states.setdefault(output, (name, path))
            if other[0] != name:
                ch.fail(path, f"joint-state name {output!r} is also produced by {other[1]} "
                              f"(a spherical joint publishes <body>_psi, _theta, _phi)")


def _body(ch: _Checker, value: Any, path: str, needs_next: bool | None,
          names: list[tuple[str, str, str]], parent: int, last: bool) -> Body | None:
    body = ch.mapping(value, path, BODY_KEYS, required=("name", "joint", "mass"))
    if body is None:
        return None
    name = ch.name(body, "name", path)
    joint = _joint(ch, body.get("joint"), _at(path, "joint"))
    written = body.get("joint").get("type") if isinstance(body.get("joint"), Mapping) else None
    joint_type = written if written in JOINT_TYPES else None  # known even if the axis is bad
    if name is not None:
        names.append((name, _at(path, "name"), joint_type or "?"))
    mass = ch.scalar(body, "mass", path, minimum=0.0)
    com = ch.vector(body, "com", path, default=np.zeros(3))
    inertia = _body_inertia(ch, body, path, mass, com)

    next_joint = ch.vector(body, "next_joint", path, default=None)
    if needs_next is None and body.get("next_joint") is not None:
        where = "the last body" if last else "a body without children"
        ch.fail(_at(path, "next_joint"), f"not allowed on {where} (there is no next joint)")
    elif needs_next and "next_joint" not in body:
        ch.fail(_at(path, "next_joint"), "required on every body but the last (s^k, from O^k to O^{k+1}), "
                                         "unless each of its children gives its joint.at")
    elif needs_next and body["next_joint"] is None:
        ch.fail(_at(path, "next_joint"), "required, got null")

    rotors = _rotors(ch, body.get("rotors"), _at(path, "rotors"), names)
    initial = _initial(ch, body.get("initial"), _at(path, "initial"), joint_type)
    visual_radius = None
    if body.get("visual") is not None:
        visual = ch.mapping(body["visual"], _at(path, "visual"), VISUAL_KEYS)
        if visual is not None:
            visual_radius = ch.scalar(visual, "radius", _at(path, "visual"), default=None,
                                      minimum=0.0, strict=True)
    if any(v is None for v in (name, joint, mass, com, inertia, rotors, initial)):
        return None
    if joint.servo is not None and not joint.servo.name:  # a servo's control is named after its body
        joint = dataclasses.replace(joint, servo=dataclasses.replace(joint.servo, name=name))
    return Body(name=name, joint=joint, mass=mass, com=_readonly(com), inertia=_readonly(inertia),
                next_joint=None if next_joint is None else _readonly(next_joint),
                rotors=rotors, initial=initial, visual_radius=visual_radius, parent=parent)


def _joint(ch: _Checker, value: Any, path: str) -> Joint | None:
    if value is None:
        return None  # missing: reported with the body's keys
    joint = ch.mapping(value, path, JOINT_KEYS, required=("type",))
    if joint is None:
        return None
    kind = ch.choice(joint, "type", path, JOINT_TYPES)
    at = ch.vector(joint, "at", path, default=None)
    at = None if at is None else _readonly(at)
    if kind == "spherical":
        if "axis" in joint:
            ch.fail(_at(path, "axis"), "not allowed for a spherical joint (only a hinge or a slide "
                                       "has an axis)")
        for key in HINGE_LIMIT_KEYS:
            if joint.get(key) is not None:
                ch.fail(_at(path, key), "not allowed for a spherical joint (only a hinge or a slide "
                                        "carries a commanded moment or force)")
        for key in HINGE_ONLY_KEYS:
            if joint.get(key) is not None:
                ch.fail(_at(path, key), "not allowed for a spherical joint (a hinge's or a slide's term)")
        return Joint(type=kind, at=at)
    if kind in ONE_AXIS_JOINTS:
        limits = _limits(ch, joint, path, HINGE_LIMIT_KEYS)
        if joint.get("axis") is None:
            ch.fail(_at(path, "axis"), f"required for a {kind} (its axis in the parent's frame)")
            return None
        axis = ch.unit(joint, "axis", path)
        armature = ch.scalar(joint, "armature", path, default=0.0, minimum=0.0)
        spring = _spring(ch, joint.get("spring"), _at(path, "spring"))
        servo = _servo(ch, joint.get("servo"), _at(path, "servo"))
        if servo and joint.get("max_torque") is not None:
            ch.fail(_at(path, "max_torque"), "not allowed with a servo (its force_range bounds it)")
            servo = False
        motor = _motor(ch, joint.get("motor"), _at(path, "motor"), axis)
        if motor and kind == "slide":
            ch.fail(_at(path, "motor"), "not allowed on a slide (a geared motor turns a hinge; a slide's "
                                        "drive takes armature)")
            motor = False
        if motor and armature:
            ch.fail(_at(path, "motor"), "not allowed with armature on the same joint (the motor is "
                                        "the exact form of the armature J gear^2)")
            motor = False
        if axis is None or limits is False or armature is None or spring is False or servo is False \
                or motor is False:
            return None
        return Joint(type=kind, axis=_readonly(axis), limits=limits, armature=armature, spring=spring,
                     servo=servo, motor=motor, at=at)
    return None


def _servo(ch: _Checker, value: Any, path: str) -> Servo | None | bool:
    """A hinge's servo (SERVO_KEYS): a Servo (its name "" until the body names it), None when
    absent, False after reporting."""
    if value is None:
        return None
    servo = ch.mapping(value, path, SERVO_KEYS)
    if servo is None:
        return False
    bad = len(ch.errors)
    name = servo.get("name", "")
    if not isinstance(name, str):
        ch.fail(_at(path, "name"), f"must be a string (got {_describe(name)})")
    gain = ch.scalar(servo, "gain", path, default=1.0)
    bias = ch.vector(servo, "bias", path, size=3, default=np.zeros(3))
    gear = ch.scalar(servo, "gear", path, default=1.0)
    control = ch.scalar(servo, "control", path, default=0.0)
    if gear == 0.0:
        ch.fail(_at(path, "gear"), "must not be zero")
    ranges = {}
    for key in ("ctrl_range", "force_range"):
        r = ch.vector(servo, key, path, size=2, default=None)
        if r is not None and not r[0] <= r[1]:
            ch.fail(_at(path, key), f"must be [low, high] with low <= high (got {r.tolist()})")
        ranges[key] = None if r is None else (float(r[0]), float(r[1]))
    if len(ch.errors) > bad or gain is None or bias is None or gear is None or control is None:
        return False
    return Servo(name=name, gain=gain, bias=tuple(float(b) for b in bias), gear=gear, control=control, **ranges)


def _motor(ch: _Checker, value: Any, path: str, hinge_axis: np.ndarray | None) -> Motor | None | bool:
    """A hinge's geared motor (MOTOR_KEYS): a Motor (its axis the hinge's unless written), None
    when absent, False after reporting."""
    if value is None:
        return None
    motor = ch.mapping(value, path, MOTOR_KEYS, required=("inertia", "gear"))
    if motor is None:
        return False
    bad = len(ch.errors)
    inertia = ch.scalar(motor, "inertia", path, minimum=0.0, strict=True)
    gear = ch.scalar(motor, "gear", path)
    if gear == 0.0:
        ch.fail(_at(path, "gear"), "must not be zero (the rotor turns gear times the joint's rate)")
    axis = ch.unit(motor, "axis", path) if motor.get("axis") is not None else hinge_axis
    if len(ch.errors) > bad or inertia is None or gear is None or axis is None:
        return False
    return Motor(inertia=inertia, gear=gear, axis=_readonly(np.array(axis, dtype=float)))


def _spring(ch: _Checker, value: Any, path: str) -> Spring | None | bool:
    """A hinge's spring (SPRING_KEYS): a Spring, None when absent, False after reporting."""
    if value is None:
        return None
    spring = ch.mapping(value, path, SPRING_KEYS, required=("stiffness",))
    if spring is None:
        return False
    bad = len(ch.errors)
    stiffness = ch.scalar(spring, "stiffness", path, minimum=0.0)
    reference = ch.scalar(spring, "reference", path, default=0.0)
    if len(ch.errors) > bad or stiffness is None or reference is None:
        return False
    return Spring(stiffness=stiffness, reference=reference)


def _limits(ch: _Checker, mapping: Mapping, path: str, keys: Sequence[str]) -> Limits | None | bool:
    """The limits and friction of an actuated axis under `keys` of `mapping`: a Limits, None
    when none is written, False after reporting a problem."""
    if all(mapping.get(key) is None for key in keys):
        return None
    bad = len(ch.errors)
    max_torque = ch.scalar(mapping, "max_torque", path, default=None, minimum=0.0)
    max_speed = ch.scalar(mapping, "max_speed", path, default=None, minimum=0.0, strict=True) \
        if "max_speed" in keys else None
    friction = _friction(ch, mapping.get("friction"), _at(path, "friction"))
    if len(ch.errors) > bad:
        return False
    return Limits(max_torque=max_torque, max_speed=max_speed, friction=friction)


def _friction(ch: _Checker, value: Any, path: str) -> Friction | None:
    """A friction mapping (FRICTION_KEYS), or None (absent, or reported)."""
    if value is None:
        return None
    friction = ch.mapping(value, path, FRICTION_KEYS)
    if friction is None:
        return None
    coulomb = ch.scalar(friction, "coulomb", path, default=0.0, minimum=0.0)
    viscous = ch.scalar(friction, "viscous", path, default=0.0, minimum=0.0)
    static = ch.scalar(friction, "static", path, default=None, minimum=0.0)
    stribeck = ch.scalar(friction, "stribeck_speed", path, default=None, minimum=0.0, strict=True)
    stick = ch.scalar(friction, "stick_speed", path, default=None, minimum=0.0, strict=True)
    if (friction.get("static") is None) != (friction.get("stribeck_speed") is None):
        given, missing = ("static", "stribeck_speed") if friction.get("static") is not None \
            else ("stribeck_speed", "static")
        ch.fail(_at(path, missing), f"required with {given} (the Stribeck term needs both)")
        return None
    if static is not None and coulomb is not None and static < coulomb:
        ch.fail(_at(path, "static"), f"must be >= coulomb ({coulomb:g}), the friction at speed "
                                     f"(got {static:g})")
        return None
    if any(v is None for v in (coulomb, viscous)) or (friction.get("stick_speed") is not None and stick is None):
        return None
    return Friction(coulomb=coulomb, viscous=viscous, static=static, stribeck_speed=stribeck,
                    stick_speed=stick)


def _body_inertia(ch: _Checker, body: Mapping, path: str, mass: float | None,
                  com: np.ndarray | None) -> np.ndarray | None:
    """The carrier's inertia tensor about O^k, from either written form."""
    has_axial = body.get("inertia") is not None
    has_com = body.get("inertia_com") is not None
    if has_axial and has_com:
        ch.fail(path, "inertia and inertia_com both given; give exactly one")
        return None
    if not has_axial and not has_com:
        ch.fail(_at(path, "inertia"), "required: give inertia {axial, transverse} (about O^k) "
                                      "or inertia_com (3x3, about the centre of mass)")
        return None
    if mass == 0.0:  # a massless frame: no inertia either (docs/scene-format.md, "Massless bodies")
        return _massless_inertia(ch, body, path)
    parallel = None if mass is None or com is None else _point_mass_inertia(mass, com)
    if has_com:
        where = _at(path, "inertia_com")
        inertia_com = ch.matrix(body["inertia_com"], where, "inertia_com")
        if inertia_com is None:
            return None
        scale = float(np.max(np.abs(inertia_com)))
        asymmetry = np.abs(inertia_com - inertia_com.T)
        if np.max(asymmetry) > SYMMETRY_RTOL * scale:
            i, j = np.unravel_index(np.argmax(asymmetry), asymmetry.shape)
            ch.fail(where, f"not symmetric ([{i}][{j}] = {inertia_com[i, j]:g} but "
                           f"[{j}][{i}] = {inertia_com[j, i]:g})")
            return None
        inertia_com = 0.5 * (inertia_com + inertia_com.T)
        problem = _inertia_problem(inertia_com)
        if problem is not None:
            ch.fail(where, problem.removeprefix("is "))
            return None
        # parallel axes: I_O = I_com + m (|c|^2 1 - c c^T)
        return None if parallel is None else inertia_com + parallel
    where = _at(path, "inertia")
    form = ch.mapping(body["inertia"], where, INERTIA_KEYS, required=INERTIA_KEYS)
    if form is None:
        return None
    axial = ch.scalar(form, "axial", where, minimum=0.0, strict=True)
    transverse = ch.scalar(form, "transverse", where, minimum=0.0, strict=True)
    if axial is None or transverse is None:
        return None
    inertia = np.diag([transverse, transverse, axial])
    if 2.0 * transverse < axial * (1.0 - TRIANGLE_RTOL):
        ch.fail(where, f"principal moments violate the triangle inequality: 2 transverse "
                       f"({2.0 * transverse:g}) < axial ({axial:g})")
        return None
    if parallel is None:
        return None
    problem = _inertia_problem(inertia - parallel)
    if problem is not None:
        ch.fail(where, f"impossible mass distribution for this mass and com: the inertia about "
                       f"the centre of mass, I_O - m (|c|^2 1 - c c^T), {problem}")
        return None
    return inertia


def _massless_inertia(ch: _Checker, body: Mapping, path: str) -> np.ndarray | None:
    """The inertia of a body of mass 0: zero, written as either form (all zeros), else refused."""
    if body.get("inertia_com") is not None:
        where = _at(path, "inertia_com")
        inertia = ch.matrix(body["inertia_com"], where, "inertia_com")
    else:
        where = _at(path, "inertia")
        form = ch.mapping(body["inertia"], where, INERTIA_KEYS, required=INERTIA_KEYS)
        if form is None:
            return None
        axial = ch.scalar(form, "axial", where, minimum=0.0)
        transverse = ch.scalar(form, "transverse", where, minimum=0.0)
        inertia = None if axial is None or transverse is None else np.diag([transverse, transverse, axial])
    if inertia is None:
        return None
    if np.any(inertia != 0.0):
        ch.fail(where, "must be zero for a massless body (mass 0): a body without mass has no inertia")
        return None
    return np.zeros((3, 3))


#: a massless body's joint column whose pivot, eliminated from the tip, is at most this fraction of
#: its diagonal of the mass matrix takes no inertia: its acceleration is undetermined
MASSLESS_PIVOT_RTOL = 1e-10


def _massless_problems(scene: Scene) -> list[str]:
    """The massless bodies (mass 0) of `scene` whose joint moves nothing with inertia at the
    initial state: the mass matrix's pivots eliminated from the tip (the articulated-body
    elimination's own, D = S^T I^A S) of their columns, against the diagonal (the subtree's
    inertia about the joint as one rigid body). One error per such body, `bodies[k]: ...`."""
    from gyro_sim.dynamics import reference
    from gyro_sim.dynamics.model import compile_model, initial_state

    model = compile_model(scene)
    data = reference.Data(model)
    reference.positions(model, data, 0.0, initial_state(model))
    M = reference.mass_matrix(model, data, *reference.joint_columns(model, data))
    diagonal = np.diag(M).copy()
    A = M[::-1, ::-1].copy()  # the tip's columns first
    pivots = np.zeros(len(A))
    for i in range(len(A)):
        pivots[i] = A[i, i]
        if pivots[i] > MASSLESS_PIVOT_RTOL * diagonal[::-1][i]:
            A[i + 1:, i + 1:] -= np.outer(A[i + 1:, i], A[i, i + 1:]) / pivots[i]
    pivots = pivots[::-1]
    out = []
    for k, body in enumerate(scene.bodies):
        columns = np.flatnonzero(model.col_body == k)
        if body.mass != 0.0 or not len(columns):
            continue
        stuck = [j for j in columns if not pivots[j] > MASSLESS_PIVOT_RTOL * diagonal[j]]
        if stuck:
            what = {"hinge": "inertia about its hinge axis", "slide": "mass to move along its slide axis"}.get(
                body.joint.type, "inertia about some axis through its joint")
            out.append(f"bodies[{k}].mass: 0 (a massless frame), and what it carries has no {what} at the "
                       "initial state: its joint's acceleration is undetermined; give it a mass, or give what "
                       "it carries that inertia")
    return out


def _rotors(ch: _Checker, value: Any, path: str,
            names: list[tuple[str, str, str]]) -> tuple[Rotor, ...] | None:
    if value is None:
        return ()
    if not isinstance(value, (list, tuple)):
        ch.fail(path, f"must be a list of rotors (got {_describe(value)})")
        return None
    rotors = [_rotor(ch, item, f"{path}[{i}]", names) for i, item in enumerate(value)]
    return None if any(r is None for r in rotors) else tuple(rotors)


def _rotor(ch: _Checker, value: Any, path: str,
           names: list[tuple[str, str, str]]) -> Rotor | None:
    rotor = ch.mapping(value, path, ROTOR_KEYS,
                       required=("name", "axis", "mass", "axial_inertia", "transverse_inertia",
                                 "mode"))
    if rotor is None:
        return None
    name = ch.name(rotor, "name", path)
    if name is not None:
        names.append((name, _at(path, "name"), "rotor"))
    axis = ch.unit(rotor, "axis", path)
    position = ch.vector(rotor, "position", path, default=np.zeros(3))
    mass = ch.scalar(rotor, "mass", path, minimum=0.0)
    axial = ch.scalar(rotor, "axial_inertia", path, minimum=0.0, strict=True)
    transverse = ch.scalar(rotor, "transverse_inertia", path, minimum=0.0)
    if axial is not None and transverse is not None and \
            2.0 * transverse < axial * (1.0 - TRIANGLE_RTOL):
        ch.fail(_at(path, "transverse_inertia"),
                f"triangle inequality 2 B_i >= A_i of an axially symmetric rotor violated "
                f"(2 * {transverse:g} < {axial:g})")
        transverse = None
    mode = ch.choice(rotor, "mode", path, ROTOR_MODES)
    spin = ch.scalar(rotor, "spin", path, default=0.0)
    actuated = ch.flag(rotor, "actuated", path, default=False)
    if mode == "speed" and actuated:
        ch.fail(_at(path, "actuated"), "a speed rotor's rate is prescribed; only torque rotors "
                                       "take commanded torques")
        actuated = None
    limits = None
    if mode == "speed":
        for key in ROTOR_LIMIT_KEYS:
            if rotor.get(key) is not None:
                ch.fail(_at(path, key), "a speed rotor's rate is prescribed; limits and friction "
                                        "belong to torque rotors")
                limits = False
    else:
        limits = _limits(ch, rotor, path, ROTOR_LIMIT_KEYS)
    if limits is False or any(v is None for v in (name, axis, position, mass, axial, transverse,
                                                  mode, spin, actuated)):
        return None
    return Rotor(name=name, axis=_readonly(axis), position=_readonly(position), mass=mass,
                 axial_inertia=axial, transverse_inertia=transverse, mode=mode, spin=spin,
                 actuated=actuated, limits=limits)


def _initial(ch: _Checker, value: Any, path: str, joint_type: str | None) -> Initial | None:
    if value is None:
        value = {}
    initial = ch.mapping(value, path, INITIAL_KEYS)
    if initial is None:
        return None
    given = {key for key, item in initial.items() if item is not None}
    if joint_type == "spherical":
        for key in HINGE_INITIAL_KEYS + SLIDE_INITIAL_KEYS:
            if key in initial:
                kind = "slide" if key in SLIDE_INITIAL_KEYS else "hinge"
                ch.fail(_at(path, key), f"{kind}-joint key, not allowed on a spherical joint "
                                        f"(give euler/euler_rates or quaternion/angular_velocity)")
        if given & set(QUATERNION_KEYS):
            if given & set(EULER_KEYS):
                ch.fail(path, "mixes the Euler form (euler, euler_rates) and the quaternion form "
                              "(quaternion, angular_velocity); give one")
                return None
            if "quaternion" not in given:
                ch.fail(_at(path, "quaternion"), "required with angular_velocity "
                                                 "(the quaternion form gives both)")
                return None
            quaternion = ch.unit(initial, "quaternion", path, size=4)
            omega = ch.vector(initial, "angular_velocity", path, default=np.zeros(3))
            if quaternion is None or omega is None:
                return None
            return Initial(quaternion=_readonly(quaternion), angular_velocity=_readonly(omega))
        euler = ch.vector(initial, "euler", path, default=np.zeros(3))
        rates = ch.vector(initial, "euler_rates", path, default=np.zeros(3))
        if euler is None or rates is None:
            return None
        return Initial(euler=_readonly(euler), euler_rates=_readonly(rates))
    if joint_type in ONE_AXIS_JOINTS:  # its coordinate and rate: (position, velocity) or (angle, rate)
        own, other = ((SLIDE_INITIAL_KEYS, HINGE_INITIAL_KEYS) if joint_type == "slide"
                      else (HINGE_INITIAL_KEYS, SLIDE_INITIAL_KEYS))
        for key in EULER_KEYS + QUATERNION_KEYS + other:
            if key in initial:
                kind = ("hinge" if joint_type == "slide" else "slide") if key in other else "spherical"
                ch.fail(_at(path, key), f"{kind}-joint key, not allowed on a {joint_type} joint "
                                        f"(give {', '.join(own)})")
        q, rate = (ch.scalar(initial, key, path, default=0.0) for key in own)
        if q is None or rate is None:
            return None
        return (Initial(position=q, velocity=rate) if joint_type == "slide" else Initial(angle=q, rate=rate))
    # joint type invalid (already reported): still check the values' shapes
    for key in EULER_KEYS + ("angular_velocity",):
        ch.vector(initial, key, path, default=None)
    ch.vector(initial, "quaternion", path, size=4, default=None)
    for key in HINGE_INITIAL_KEYS + SLIDE_INITIAL_KEYS:
        ch.scalar(initial, key, path, default=None)
    return None


def _imus(ch: _Checker, value: Any, bodies: Any) -> tuple[Imu, ...] | None:
    """The IMUs: names unique and not a body's (an IMU's name is its frame), each on a body."""
    if value is None:
        return ()
    if not isinstance(value, (list, tuple)):
        ch.fail("imus", f"must be a list of IMUs (got {_describe(value)})")
        return None
    body_names = [b.get("name") for b in bodies if isinstance(b, Mapping)] \
        if isinstance(bodies, (list, tuple)) else []
    seen: dict[str, str] = {}
    tokens: dict[str, tuple[str, str]] = {}
    imus = []
    for index, item in enumerate(value):
        path = f"imus[{index}]"
        imu = _imu(ch, item, path, body_names)
        imus.append(imu)
        name = item.get("name") if isinstance(item, Mapping) else None
        if not isinstance(name, str):
            continue
        where = _at(path, "name")
        if name in seen:
            ch.fail(where, f"duplicate name {name!r} (also at {seen[name]}); IMU names must be unique")
        elif name in body_names:
            ch.fail(where, f"{name!r} is a body's name; an IMU's name is its frame_id and must "
                           f"differ from the bodies' frames")
        elif tokens.get(topic_token(name), (name,))[0] != name:
            other = tokens[topic_token(name)]
            ch.fail(where, f"{name!r} and {other[0]!r} (at {other[1]}) make the same topic "
                           f"~/imu/{topic_token(name)}; rename one")
        seen.setdefault(name, where)
        tokens.setdefault(topic_token(name), (name, where))
    return None if any(imu is None for imu in imus) else tuple(imus)


def _imu(ch: _Checker, value: Any, path: str, body_names: list) -> Imu | None:
    imu = ch.mapping(value, path, IMU_KEYS, required=("name", "body"))
    if imu is None:
        return None
    name = ch.name(imu, "name", path)
    body = imu.get("body")
    if body is not None and (not isinstance(body, str) or body not in body_names):
        known = ", ".join(str(b) for b in body_names if isinstance(b, str))
        got = repr(body) if isinstance(body, str) else _describe(body)
        ch.fail(_at(path, "body"), f"no body named {got} (bodies: {known})")
        body = None
    position = ch.vector(imu, "position", path, default=np.zeros(3))
    orientation = ch.unit(imu, "orientation", path, size=4, default=np.array([1.0, 0.0, 0.0, 0.0]))
    rate = None
    if imu.get("rate") is not None:  # Hz: the bound of a frequency, not that of the joint `rate`
        rate = ch.number(imu["rate"], _at(path, "rate"), "frequency")
        if rate is not None and rate <= 0.0:
            ch.fail(_at(path, "rate"), f"must be > 0 (got {rate!r})")
            rate = None
        elif rate is None:
            return None
    noise = {key: ch.scalar(imu, key, path, default=0.0, minimum=0.0) for key in IMU_NOISE_KEYS}
    seed = imu.get("seed", 0)
    if seed is None:
        seed = 0
    if isinstance(seed, (bool, np.bool_)) or not isinstance(seed, numbers.Integral) \
            or not 0 <= seed <= MAX_IMU_SEED:
        ch.fail(_at(path, "seed"), f"must be an integer from 0 to 2^64 - 1 (got {_describe(seed)})")
        seed = None
    if any(v is None for v in (name, body, position, orientation, seed, *noise.values())):
        return None
    return Imu(name=name, body=body, position=_readonly(position), orientation=_readonly(orientation),
               rate=rate, seed=int(seed), **noise)
