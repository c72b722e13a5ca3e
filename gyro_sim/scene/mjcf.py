"""MJCF and URDF models as gyro_sim scenes: the mapping of docs/models.md.

MuJoCo (the optional ``mujoco`` package, extra ``[models]``) reads the file
(``MjSpec.from_file``: MJCF, or URDF by its ``<robot>`` root) and compiles it; everything is
taken from the compiled ``MjModel`` and from MuJoCo's own kinematics, so a body's mass, centre
of mass and inertia are the ones MuJoCo simulates (also when it derives them from geoms):

- bodies without a joint are welded to their parent: on the world they are part of the base,
  on a moving body they are merged into it (masses and inertias added);
- a **rotor** is a body on a hinge, with no moving child, whose centre of mass lies on the
  hinge axis and whose inertia is symmetric about it (both to ``ROTOR_RTOL``): it becomes a
  torque rotor of its parent (eqs (18)-(19), (29)), actuated when a motor drives its joint
  (every rotor of a URDF model is);
- the other bodies form the tree, every parent before its children (depth first in MuJoCo's
  order: a chain keeps its order, and a body's first child follows it); a body that is not its
  parent's first child names its `parent` (``base`` for the world) and its joint point
  `joint.at`; a free joint on the body on the world is the free base (with a spherical joint
  at O^1; it carries the whole tree), ball joints are spherical joints, hinges are hinges,
  slides slides (the body keeps its parent's frame, moved along the axis);
- a body with several hinge and slide joints j1..jm (MuJoCo applies them in order) is m scene
  bodies: a massless frame at the anchor of each of j1..j(m-1), then the body on jm.

Frames. A body's frame in the scene has its origin at its joint point O^k (the joint's
anchor; for a free joint the body's origin). A ball or free body's frame turns with the MuJoCo
body frame and equals it in rotation (its quaternion is MuJoCo's ``xquat``); a hinge body's
frame is its parent's frame at the model's reference pose, turned by the hinge angle, as
docs/scene-format.md defines it, so the hinge axis is written in the parent's frame. The
reference pose is MuJoCo's ``qpos0`` with every hinge and slide at 0 (a joint's ``ref`` only
says where the file draws its body), so that a hinge's angle and a slide's position are
MuJoCo's ``qpos``. Every vector of the scene is MuJoCo's world vector at the reference pose,
rotated into that frame.

Names: a hinge, a slide and a rotor are named after their joint (so ``joint_states`` and the axis
moments use the joint names of the file, as MuJoCo's ``qpos`` and actuators do), a ball or
free body after its body.

Sensors. A gyro or an accelerometer on a site (a framequat or framelinacc of the same site
joins them) becomes one IMU of the scene, named after the site, on the scene body the site
moves with, at the site's pose in that body's frame at the reference pose; a URDF's Gazebo
IMUs (:mod:`gyro_sim.scene.gazebo`) become sites on their links first, so MuJoCo carries them
through fused fixed links. A rate is MuJoCo's ``interval`` or Gazebo's ``update_rate``, kept
as given; a noise's standard deviation per sample sigma becomes the density sigma / sqrt(rate)
(the default publish rate when none is given). Every other sensor is named in a note.

A slide joint becomes a body's `slide` (its terms as a hinge's). A hinge's or rotor's joint damping
and frictionloss become its `friction` (viscous and
Coulomb); a hinge's armature and its spring (stiffness, springref) its `armature` and
`spring` (docs/models.md, "Armature and joint springs"); a model's affine actuators (position,
velocity, general with an affine bias) its hinges' `servo`, motors too (docs/models.md, "Servo
actuators"). Everything the equations of gyro_sim cannot express (tendons, equality
constraints, a ball joint's damping, spring or armature, a variable gain, a free body beside
other bodies on the world, an inertia outside the triangle inequality on a moving body unless
``balance_inertia``, ...) is refused, one line per element and every problem of the file in
one refusal; contacts, joint limits and control ranges are ignored and listed in
:attr:`ImportedModel.notes`, as are missing meshes and textures that no moving body's mass
needs. This module raises :class:`ModelError`; ``gyro_sim.scene.load.load_scene`` turns it
into a ``SceneError``.
"""
from __future__ import annotations

import contextlib
import math
import os
import re
import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from gyro_sim.dynamics.imu import DEFAULT_IMU_RATE, divides
from gyro_sim.dynamics.rotations import matrix_to_quat, quat_mul, quat_to_matrix
from gyro_sim.errors import GyroSimError
from gyro_sim.paths import MODEL_SUFFIXES
from gyro_sim.scene.gazebo import GazeboImu, GazeboSensors, read_gazebo_sensors
from gyro_sim.scene.packages import PackageResolver
from gyro_sim.scene.robot import RobotDescription, describe_robot

__all__ = ["ModelError", "ImportedModel", "Command", "caught_warnings", "import_model", "is_model_path", "parse_locks",
           "scene_yaml", "MODEL_SUFFIXES", "ROTOR_RTOL"]

#: a body on a hinge is a rotor when its centre of mass is off the hinge axis by at most this
#: fraction of its radius of gyration, and its inertia about the centre of mass differs from
#: an axially symmetric one by at most this fraction of its largest moment
ROTOR_RTOL = 1e-9
#: numbers are written as the shortest decimal within this fraction of their scale (a vector's
#: or tensor's largest entry): the rounding of MuJoCo's and the frame changes' arithmetic, far
#: below any physical effect, is not written out
TIDY_RTOL = 32 * np.finfo(float).eps
#: largest model file read (a robot's MJCF or URDF is kilobytes; meshes are separate files)
MAX_MODEL_BYTES = 64 * 2**20
#: what installs MuJoCo
INSTALL_HINT = "pip install 'gyro_sim[models]'"


class ModelError(GyroSimError, ValueError):
    """A model that cannot become a scene. `errors` lists every problem, one line each, as
    ``<file>: <element>: <why>``."""

    def __init__(self, errors: Sequence[str], path: str | None = None):
        self.errors = list(errors)
        self.path = path
        super().__init__("\n".join(self.errors))


@dataclass(frozen=True)
class Command:
    """How a MuJoCo control maps onto a gyro_sim axis moment: moment = factor x ctrl."""

    actuator: str  # the actuator's name in the model
    axis: str  # the gyro_sim axis (hinge or rotor) it drives
    factor: float  # gear x gain: N m per unit of ctrl


@dataclass(frozen=True)
class ImportedModel:
    """A model read as a scene mapping, with what the mapping did to it."""

    mapping: dict  # the scene, as docs/scene-format.md (validated by load_scene)
    path: str  # the model file
    kind: str  # "MJCF" or "URDF"
    keyframe: str | None  # the keyframe the initial state comes from ("" unnamed), None: rest
    names: tuple[tuple[str, str], ...]  # (model element, scene name), in the scene's order, then the IMUs
    commands: tuple[Command, ...]  # the model's actuators
    notes: tuple[str, ...]  # what was left out or approximated (contacts, limits, sensors...), one line each
    where: dict[str, str] = field(default_factory=dict)  # scene key path -> model element
    robot: RobotDescription | None = None  # a URDF's own description and link frames (None: MJCF)

    def describe(self, errors: Sequence[str]) -> list[str]:
        """`load_scene`'s errors on :attr:`mapping` with key paths named by model elements
        (``bodies[1].mass: ...`` -> ``robot.xml: body 'upper': mass: ...``)."""
        keys = sorted(self.where, key=len, reverse=True)

        def element(match: re.Match) -> str:  # a key path named in a rule: its element only
            return self.where[match.group(1)]

        pattern = re.compile("(" + "|".join(re.escape(k) for k in keys) + r")(?:\.\w+)*") if keys else None
        out = []
        for error in errors:
            key, _, rule = error.partition(": ")
            head = next((k for k in keys if key == k or key.startswith(k + ".")), None)
            if pattern is not None:
                rule = pattern.sub(element, rule)
            if head is None:
                out.append(f"{self.path}: {key}: {rule}")
            else:
                rest = key[len(head) + 1:]
                out.append(f"{self.path}: {self.where[head]}: " + (f"{rest}: " if rest else "") + rule)
        return out


def is_model_path(path: str | os.PathLike) -> bool:
    """Whether `path` names an MJCF or URDF model (by its suffix: ``MODEL_SUFFIXES``)."""
    return os.path.splitext(os.fspath(path))[1].lower() in MODEL_SUFFIXES


# ----------------------------------------------------------------------------- numbers
def _tidy(x: float, scale: float | None = None) -> float:
    """`x` as the shortest decimal within TIDY_RTOL x `scale` (default |x|) of it."""
    x = float(x)
    tolerance = TIDY_RTOL * (abs(x) if scale is None else scale)
    if abs(x) <= tolerance or not math.isfinite(x):
        return 0.0 if abs(x) <= tolerance else x
    for digits in range(1, 18):
        y = float(f"{x:.{digits}g}")
        if abs(y - x) <= tolerance:
            return y
    return x


def _vec(v: np.ndarray) -> list[float]:
    v = np.asarray(v, dtype=float).ravel()
    scale = float(np.max(np.abs(v))) if v.size else 0.0
    return [_tidy(x, scale) for x in v]


def _mat(a: np.ndarray) -> list[list[float]]:
    a = 0.5 * (a + a.T)
    scale = float(np.max(np.abs(a)))
    return [[_tidy(x, scale) for x in row] for row in a]


# ----------------------------------------------------------------------------- reading
def import_model(path: str | os.PathLike, keyframe: str | None = None,
                 package_path: Sequence[str | os.PathLike] = (),
                 lock: Mapping[str, float | None] | Sequence[str] = (),
                 balance_inertia: bool = False, geared_motors: float | None = None) -> ImportedModel:
    """Read an MJCF or URDF model as a scene mapping (module docstring, docs/models.md).

    Parameters
    ----------
    path : the model file: MJCF, or URDF (a ``<robot>`` root), whatever its suffix
    keyframe : the name of the keyframe giving the initial state; None: the model's first
        keyframe, or the reference pose at rest when it has none; "none" (unless a keyframe has
        that name): the reference pose at rest
    package_path : directories searched first for the packages of ``package://`` URIs
        (:mod:`gyro_sim.scene.packages`)
    lock : joints welded where they are: a mapping joint name -> value (rad or m; None: the
        keyframe's value, else the reference position), or a sequence of names
    balance_inertia : a moving body's inertia that breaks the triangle inequality A + B >= C
        of its principal moments is replaced by MuJoCo's balanced one (the three set to their
        mean, MuJoCo's ``balanceinertia``) with a note, instead of refused
    geared_motors : a gear ratio G: every hinge's armature a becomes the geared motor it reflects,
        a rotor of axial inertia a / G^2 on the parent turning G times the joint's rate
        (docs/models.md, "The geared motor against the armature"); None: the armature

    Raises
    ------
    ModelError
        Listing every element that cannot be mapped (or why the file cannot be read), all
        at once.
    """
    path = os.fspath(path)
    try:
        import mujoco
    except ImportError:
        raise ModelError([f"{path}: reading an MJCF or URDF model needs mujoco, not installed; "
                          f"install it with: {INSTALL_HINT}"], path) from None
    if geared_motors is not None and not (math.isfinite(geared_motors) and geared_motors != 0.0):
        raise ModelError([f"geared_motors: the gear ratio must be a finite non-zero number (got {geared_motors!r})"],
                         path)
    if not os.path.exists(path):
        raise ModelError([f"{path}: file not found"], path)
    if not os.path.isfile(path):
        raise ModelError([f"{path}: not a file"], path)
    size = os.path.getsize(path)
    if size > MAX_MODEL_BYTES:
        raise ModelError([f"{path}: {size} bytes, more than a model file holds "
                          f"(at most {MAX_MODEL_BYTES})"], path)
    kind = _kind(path)
    gazebo: GazeboSensors | None = None
    sites: list[tuple[GazeboImu, str]] = []
    resolver = PackageResolver(path, [os.fspath(p) for p in package_path])
    notes: list[str] = []
    errors: list[str] = []  # every problem found, said together (one refusal)
    locked: dict[str, float] = {}
    with caught_warnings(mujoco) as warned:
        try:
            spec = mujoco.MjSpec.from_file(path)
            locks = parse_locks(lock, path) if lock else {}
            static = _static_bodies(spec, set(locks))
            errors += _prepare_assets(spec, path, resolver, notes, static)
            errors += _balance_inertias(spec, path, static, balance_inertia, notes)
            if locks:
                errors += _lock_joints(mujoco, spec, spec.compile(), path, locks, keyframe, locked, notes)
            if kind == "URDF":
                gazebo = read_gazebo_sensors(path)
                sites = _gazebo_sites(spec, gazebo)
            model = spec.compile()
        except ValueError as exc:  # MuJoCo's parse and compile errors
            if isinstance(exc, ModelError):
                raise ModelError(errors + exc.errors, path) from None
            text = "; ".join(line.strip() for line in str(exc).splitlines() if line.strip())
            raise ModelError(errors + [f"{path}: MuJoCo cannot read it: {text}"], path) from None
    notes = resolver.notes() + notes + [f"MuJoCo: {w}" for w in dict.fromkeys(warned)]
    importer = _Importer(mujoco, model, path, kind, gazebo, sites)
    importer.errors += errors
    importer.notes += notes
    importer.locked = locked
    importer.gear = geared_motors
    return importer.run(keyframe)


def parse_locks(lock: Mapping[str, float | None] | Sequence[str], path: str | None = None) -> dict[str, float | None]:
    """Joints to lock as a mapping name -> value (None: the keyframe's, else the reference):
    from a mapping, or from ``NAME`` / ``NAME=VALUE`` strings (``--lock``, the node's ``lock``
    parameter). Raises ModelError naming a value that is no finite number."""
    if isinstance(lock, Mapping):
        items = list(lock.items())
    else:
        items = []
        for text in lock:
            name, sep, value = str(text).partition("=")
            items.append((name.strip(), value.strip() if sep else None))
    out: dict[str, float | None] = {}
    where = f"{path}: " if path else ""
    for name, value in items:
        if value is not None and not isinstance(value, (bool, np.bool_)):
            try:
                value = float(value)
            except (TypeError, ValueError):
                value = None if value is None else math.nan
        elif value is not None:
            value = math.nan
        if value is not None and not math.isfinite(value):
            raise ModelError([f"{where}lock: joint {name!r}: the value must be a finite number (NAME=VALUE, rad or m)"],
                             path)
        out[name] = value
    return out


def _lock_joints(mujoco: Any, spec: Any, m0: Any, path: str, locks: dict[str, float | None],
                 keyframe: str | None, locked: dict[str, float], notes: list[str]) -> list[str]:
    """Weld the joints of `locks` in `spec` where they are (docs/models.md, "Locked joints"):
    each child body turned (hinge) or moved (slide) to the joint's value from the reference
    position, then the joint deleted, so that MuJoCo's compiler merges the body into its parent
    (or, in a body with several joints, the body's joints before it moved back through that
    turn, so that they act after it as they did before it);
    the actuators, equalities and sensors of a locked joint deleted with a note, keyframes
    without its entries. `m0`: the model compiled before; `locked` gains (name, value) in the
    file's order. The errors."""
    obj, jt = mujoco.mjtObj, mujoco.mjtJoint
    errors = []
    key = None
    if keyframe is not None:
        key = mujoco.mj_name2id(m0, obj.mjOBJ_KEY, keyframe)
        key = None if key < 0 else key  # an unknown keyframe is said by the importer
    elif m0.nkey:
        key = 0
    joints = {}
    for name in locks:
        j = mujoco.mj_name2id(m0, obj.mjOBJ_JOINT, name) if name else -1
        if j < 0:
            named = [mujoco.mj_id2name(m0, obj.mjOBJ_JOINT, i) for i in range(m0.njnt)]
            errors.append(f"{path}: lock: no joint named {name!r} (the model's: "
                          + ", ".join(repr(n) for n in named if n) + ")")
        elif int(m0.jnt_type[j]) in (int(jt.mjJNT_FREE), int(jt.mjJNT_BALL)) and locks[name] is not None:
            errors.append(f"{path}: lock: joint {name!r} is a {('free', 'ball')[int(m0.jnt_type[j])]} joint: it "
                          "is locked where it is (its keyframe's pose, else the file's), without a value")
        else:
            joints[name] = j  # the others are said, and these locked all the same (one refusal)
    removed_q: list[int] = []
    removed_a: list[int] = []
    for name, j in sorted(joints.items(), key=lambda item: item[1]):
        joint = spec.joint(name)
        body = joint.parent
        qa = int(m0.jnt_qposadr[j])
        if int(m0.jnt_type[j]) in (int(jt.mjJNT_FREE), int(jt.mjJNT_BALL)):
            removed_q += _weld_spherical(mujoco, spec, m0, j, body, key)
            removed_a += [a for a in range(m0.nu) if int(m0.actuator_trnid[a][0]) == j]
            locked[name] = 0.0  # no coordinate of its own: its pose is the body's in the spec now
            notes.append(f"joint {name!r}: locked at its {'keyframe' if key is not None else 'reference'} "
                         "pose (its body welded to its parent)")
            continue
        ref = float(m0.qpos0[qa])
        value = locks[name]
        if value is None:
            value = float(m0.key_qpos[key][qa]) if key is not None else ref
        value = float(value)
        if not math.isfinite(value):
            errors.append(f"{path}: lock: joint {name!r}: the value must be finite (got {value!r})")
            continue
        pos = np.asarray(joint.pos, dtype=float)
        axis = np.asarray(joint.axis, dtype=float)
        axis = axis / np.linalg.norm(axis)
        delta = value - ref
        quat = np.asarray(body.quat if body.alt.type == mujoco.mjtOrientation.mjORIENTATION_QUAT else
                          spec.resolve_orientation(spec.compiler.degree, spec.compiler.eulerseq, body.alt),
                          dtype=float)
        quat = quat / np.linalg.norm(quat)
        R = quat_to_matrix(quat)
        if int(m0.jnt_type[j]) == int(jt.mjJNT_HINGE):
            turn = np.concatenate([[math.cos(0.5 * delta)], math.sin(0.5 * delta) * axis])
            T = quat_to_matrix(turn)
            body.pos = np.asarray(body.pos, dtype=float) + R @ (pos - T @ pos)
            body.quat = quat_mul(quat, turn)
            body.alt.type = mujoco.mjtOrientation.mjORIENTATION_QUAT
        else:
            T = np.eye(3)
            body.pos = np.asarray(body.pos, dtype=float) + R @ (delta * axis)
        # MuJoCo applies a body's joints in order, X_B R_1 ... R_j ...: with R_j now in X_B, each
        # joint before it (not locked) becomes R_j^-1 R_p R_j, its line moved by R_j^-1 (x -> T^T (x -
        # pos - delta axis) + pos, axes by T^T)
        first = int(m0.body_jntadr[m0.jnt_bodyid[j]])
        shift = delta * axis if int(m0.jnt_type[j]) == int(jt.mjJNT_SLIDE) else np.zeros(3)
        for p in range(first, j):
            if p in joints.values():
                continue
            before = body.joints[p - first]
            before.pos = T.T @ (np.asarray(before.pos, dtype=float) - pos - shift) + pos
            before.axis = T.T @ np.asarray(before.axis, dtype=float)
        removed_q.append(qa)
        removed_a += [a for a in range(m0.nu) if int(m0.actuator_trnid[a][0]) == j and
                      int(m0.actuator_trntype[a]) in (int(mujoco.mjtTrn.mjTRN_JOINT),
                                                      int(mujoco.mjtTrn.mjTRN_JOINTINPARENT))]
        locked[name] = value
        notes.append(f"joint {name!r}: locked at {value:g} (its body welded to its parent)")
    actuators, all_tendons = list(spec.actuators), list(spec.tendons)  # by the compiled model's ids
    for a in removed_a:
        notes.append(f"actuator {actuators[a].name or '(unnamed)'!r}: left out with the joint it drives "
                     f"{actuators[a].target!r} (locked)")
    for equality in list(spec.equalities):
        if equality.type == mujoco.mjtEq.mjEQ_JOINT and (equality.name1 in locked or equality.name2 in locked):
            notes.append(f"equality {equality.name or '(unnamed)'!r}: left out with the locked "
                         f"joint {equality.name1 if equality.name1 in locked else equality.name2!r}")
            spec.delete(equality)
    tendons = _locked_tendons(mujoco, m0, set(joints.values()))
    for t in tendons:  # a tendon on locked joints only moves nothing: it goes, with what acts on it
        name = all_tendons[t].name
        shown = repr(name) if name else f"#{t}"
        for a in range(m0.nu):
            if int(m0.actuator_trntype[a]) == int(mujoco.mjtTrn.mjTRN_TENDON) and int(m0.actuator_trnid[a][0]) == t:
                notes.append(f"actuator {actuators[a].name or '(unnamed)'!r}: left out with the tendon "
                             f"{shown} it drives")
                removed_a.append(a)
        for sensor in list(spec.sensors):
            if name and sensor.objtype == obj.mjOBJ_TENDON and sensor.objname == name:
                notes.append(f"sensor {sensor.name or '(unnamed)'!r}: left out with the tendon {shown}")
                spec.delete(sensor)
        for equality in list(spec.equalities):  # a coupling of the tendon's length goes with it
            if name and equality.type == mujoco.mjtEq.mjEQ_TENDON and name in (equality.name1, equality.name2):
                notes.append(f"equality {equality.name or '(unnamed)'!r}: left out with the tendon {shown}")
                spec.delete(equality)
        notes.append(f"tendon {shown}: left out, its joints are all locked")
    removed_a = sorted(set(removed_a))
    for a in removed_a:
        spec.delete(actuators[a])
    for t in tendons:
        spec.delete(all_tendons[t])
    for sensor in list(spec.sensors):
        if sensor.objtype == obj.mjOBJ_JOINT and sensor.objname in locked:
            notes.append(f"sensor {sensor.name or '(unnamed)'!r}: left out with the locked joint "
                         f"{sensor.objname!r}")
            spec.delete(sensor)
    # the joints first, then the keyframes' entries (MuJoCo 4.0's MjSpec.delete checks the
    # keyframes' sizes against the joints still there)
    for name in joints:
        spec.delete(spec.joint(name))
    removed_v = [d for j in joints.values() for d in range(int(m0.jnt_dofadr[j]),
                                                           int(m0.jnt_dofadr[j]) + _DOFS[int(m0.jnt_type[j])])]
    for k in spec.keys:
        if len(k.qpos) == m0.nq:
            k.qpos = np.delete(np.asarray(k.qpos), removed_q)
        if len(k.qvel) == m0.nv:
            k.qvel = np.delete(np.asarray(k.qvel), removed_v)
        if len(k.act) == m0.na and m0.na and removed_a:
            k.act = np.delete(np.asarray(k.act), [int(m0.actuator_actadr[a]) for a in removed_a
                                                  if int(m0.actuator_actadr[a]) >= 0])
        if len(k.ctrl) == m0.nu and removed_a:
            k.ctrl = np.delete(np.asarray(k.ctrl), removed_a)
    return errors


#: the coordinates (qpos) and the velocities (qvel) of MuJoCo's joint types: free, ball, slide, hinge
_QPOS = (7, 4, 1, 1)
_DOFS = (6, 3, 1, 1)


def _weld_spherical(mujoco: Any, spec: Any, m0: Any, j: int, body: Any, key: int | None) -> list[int]:
    """Weld the ball or free joint `j` of `body` where it stands: at keyframe `key` (None: the
    reference, qpos0), the body turned through its anchor by the ball's quaternion, or a free
    body (on the world) placed at its pose; its qpos entries."""
    kind = int(m0.jnt_type[j])
    qa = int(m0.jnt_qposadr[j])
    q = np.asarray(m0.key_qpos[key] if key is not None else m0.qpos0, dtype=float)[qa:qa + _QPOS[kind]]
    if kind == int(mujoco.mjtJoint.mjJNT_FREE):
        body.pos = q[:3]
        body.quat = q[3:] / np.linalg.norm(q[3:])
    else:
        turn = q / np.linalg.norm(q)
        quat = np.asarray(body.quat if body.alt.type == mujoco.mjtOrientation.mjORIENTATION_QUAT else
                          spec.resolve_orientation(spec.compiler.degree, spec.compiler.eulerseq, body.alt),
                          dtype=float)
        quat = quat / np.linalg.norm(quat)
        pos = np.asarray(spec.joint(mujoco.mj_id2name(m0, mujoco.mjtObj.mjOBJ_JOINT, j)).pos, dtype=float)
        body.pos = np.asarray(body.pos, dtype=float) + quat_to_matrix(quat) @ (pos - quat_to_matrix(turn) @ pos)
        body.quat = quat_mul(quat, turn)
    body.alt.type = mujoco.mjtOrientation.mjORIENTATION_QUAT
    return list(range(qa, qa + _QPOS[kind]))


def _locked_tendons(mujoco: Any, m0: Any, joints: set[int]) -> list[int]:
    """The tendons of `m0` (fixed tendons) whose every joint is among the locked `joints`."""
    out = []
    for t in range(m0.ntendon):
        first, count = int(m0.tendon_adr[t]), int(m0.tendon_num[t])
        wraps = range(first, first + count)
        if count and all(int(m0.wrap_type[w]) == int(mujoco.mjtWrap.mjWRAP_JOINT)
                         and int(m0.wrap_objid[w]) in joints for w in wraps):
            out.append(t)
    return out


@contextlib.contextmanager
def caught_warnings(mujoco: Any):
    """MuJoCo's warnings (its parser's and compiler's ``WARNING: ...`` lines), collected into
    the list yielded instead of printed; the previous handler restored after."""
    caught: list[str] = []
    previous = mujoco.get_mju_user_warning()
    mujoco.set_mju_user_warning(lambda message: caught.append(str(message).strip()))
    try:
        yield caught
    finally:
        mujoco.set_mju_user_warning(previous)


#: the mesh files MuJoCo reads (by suffix); others (COLLADA .dae ...) are left out as missing
MUJOCO_MESHES = (".stl", ".obj", ".msh")


def _static_bodies(spec: Any, locked: set[str]) -> set[str]:
    """The names of the bodies welded to the world: neither they nor a body above them has a
    joint other than the `locked` ones (the world included, as "world")."""
    out: set[str] = set()

    def visit(body: Any, static: bool) -> None:
        static = static and all(j.name in locked and j.name for j in body.joints)
        if static:
            out.add(body.name)
        for child in body.bodies:
            visit(child, static)

    visit(spec.worldbody, True)
    return out


def _prepare_assets(spec: Any, path: str, resolver: PackageResolver, notes: list[str],
                    static: set[str]) -> list[str]:
    """Every mesh and texture file of `spec` resolved (``package://``, ``file://``, relative
    paths: :mod:`gyro_sim.scene.packages`) to an absolute path. A mesh that cannot be found or
    read is left out with its geoms and one note, unless a moving body's mass comes from it:
    then an error naming the body and the file (a body welded to the world, `static`, needs no
    mass: a note). A texture that cannot be found is left out with a note (nothing moves by
    it). The errors; the meshes they name are left out too, so that the rest is still
    checked."""
    import mujoco

    model_dir = os.path.dirname(os.path.abspath(path))
    base = os.path.join(model_dir, spec.meshdir) if spec.meshdir else model_dir
    from_geoms = spec.compiler.inertiafromgeom
    always = from_geoms == mujoco.mjtInertiaFromGeom.mjINERTIAFROMGEOM_TRUE
    never = from_geoms == mujoco.mjtInertiaFromGeom.mjINERTIAFROMGEOM_FALSE
    errors = []
    kind = "link" if _kind(path) == "URDF" else "body"
    left: list[tuple[str, list[str], str, list[str]]] = []  # (shown, bodies, why, welded) of each mesh left out
    for mesh in list(spec.meshes):
        if not mesh.file:
            continue  # vertices given inline
        file, shown, why = _asset_file(resolver, mesh.file, base, MUJOCO_MESHES, "meshes")
        if why is None:
            mesh.file = file
            continue
        geoms = [g for g in spec.geoms if g.meshname == mesh.name]
        bodies = list(dict.fromkeys(g.parent.name for g in geoms))
        needs = [b for b in bodies if b and b not in static and not never
                 and (always or not spec.body(b).explicitinertial)]
        for b in needs:
            errors.append(f"{path}: {kind} {b!r}: its mass would come from the mesh {shown}, "
                          f"which cannot be read: {why}; give the {kind} an inertial or the "
                          "mesh (--package-path DIR)")
        for g in geoms:
            spec.delete(g)
        spec.delete(mesh)
        fixed = [b for b in bodies if b in static and b != "world" and not never
                 and (always or not spec.body(b).explicitinertial)]
        for b in needs + fixed:  # a stand-in mass: what is welded to the world moves nothing, and
            body = spec.body(b)  # a moving body is refused all the same (the rest is still checked)
            body.explicitinertial, body.mass, body.inertia = True, 1.0, [1.0, 1.0, 1.0]
        if not needs and geoms:  # an asset no geom uses is left out unsaid
            left.append((shown, bodies, why, fixed))
    if left:  # one note for all (a description without its meshes misses them all)
        fixed = list(dict.fromkeys(b for entry in left for b in entry[3]))
        welded = (f"{', '.join(repr(b) for b in fixed)} welded to the world need{'s' if len(fixed) == 1 else ''} "
                  "no mass")
        why_not = (welded if fixed and all(entry[3] for entry in left) else
                   f"masses and inertias are given, {welded}" if fixed else "masses and inertias are given")
        shown, bodies, why, _ = left[0]
        if len(left) == 1:
            on = f" (on {', '.join(repr(b) for b in bodies)})" if bodies else ""
            notes.append(f"mesh {shown}{on}: left out, {why}; the motion does not need it ({why_not})")
        else:
            more = f" and {len(left) - 3} more" if len(left) > 3 else ""
            notes.append(f"{len(left)} meshes left out with their geoms ({', '.join(e[0] for e in left[:3])}{more}): "
                         f"they cannot be read (the first: {why}); the motion does not need them ({why_not})")
    texture_dir = os.path.join(model_dir, spec.texturedir) if spec.texturedir else model_dir
    for texture in list(spec.textures):
        if not texture.file:
            continue  # builtin
        file, shown, why = _asset_file(resolver, texture.file, texture_dir, None, "textures")
        if why is None:
            texture.file = file
            continue
        name = texture.name
        for material in spec.materials:
            material.textures = ["" if t == name else t for t in material.textures]
        spec.delete(texture)
        notes.append(f"texture {shown}: left out, {why}; nothing moves by it")
    return errors


def _asset_file(resolver: PackageResolver, uri: str, base: str, suffixes: Sequence[str] | None,
                what: str) -> tuple[str | None, str, str | None]:
    """(the file, how to show it, None) of an asset's `uri`, or (None, shown, why it cannot be
    read)."""
    file, shown = resolver.resolve(uri, base)
    if file is None:
        return None, shown, f"package {shown[len('package://'):].partition('/')[0]!r} not found"
    if not os.path.isfile(file):
        return None, shown, f"no such file ({file})"
    if suffixes is not None and os.path.splitext(file)[1].lower() not in suffixes:
        return None, shown, f"MuJoCo reads {', '.join(suffixes)} {what} only"
    return file, shown, None


def _principal_moments(body: Any) -> np.ndarray | None:
    """A body's explicit principal moments of inertia (ascending), None without an inertial."""
    if not body.explicitinertial:
        return None
    full = np.asarray(body.fullinertia, dtype=float)
    if np.all(np.isfinite(full)):
        xx, yy, zz, xy, xz, yz = full
        return np.linalg.eigvalsh(np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]]))
    return np.sort(np.asarray(body.inertia, dtype=float))


#: principal moments A <= B <= C break the triangle inequality when A + B < C (1 - this)
TRIANGLE_SLACK = 1e-12


def _balance_inertias(spec: Any, path: str, static: set[str], balance: bool, notes: list[str]) -> list[str]:
    """Bodies whose explicit inertia breaks the triangle inequality A + B >= C of its
    principal moments (docs/models.md, "Inertias outside the triangle inequality"), which
    MuJoCo refuses: on a body welded to the world (`static`) the three moments are set to
    their mean with a note (nothing moves by it); on a moving body too when `balance`
    (``--balance-inertia``: MuJoCo's balanceinertia), else an error naming the body. The
    errors (their bodies are balanced all the same, so that the rest is still checked)."""
    errors = []
    kind = "link" if _kind(path) == "URDF" else "body"
    for body in spec.bodies:
        moments = _principal_moments(body)
        if moments is None or moments[0] + moments[1] >= moments[2] * (1.0 - TRIANGLE_SLACK):
            continue
        shown = ", ".join(f"{x:.6g}" for x in moments)
        mean = float(np.mean(moments))
        if body.name in static or balance:
            why = "welded to the world, it moves nothing" if body.name in static else "--balance-inertia"
            notes.append(f"{kind} {body.name!r}: principal moments ({shown}) break A + B >= C; set to "
                         f"their mean {mean:.6g} ({why})")
        else:
            errors.append(f"{path}: {kind} {body.name!r}: principal moments of inertia ({shown}) break "
                          "the triangle inequality A + B >= C (no mass distribution has them; MuJoCo "
                          "refuses them); --balance-inertia sets them to their mean, as MuJoCo's "
                          "balanceinertia does")
        # MuJoCo's balanceinertia: the principal frame kept, the three moments their mean
        full = np.asarray(body.fullinertia, dtype=float)
        if np.all(np.isfinite(full)):
            body.fullinertia = [mean, mean, mean, 0.0, 0.0, 0.0]
        else:
            body.inertia = [mean, mean, mean]
    return errors


#: the sites put where the Gazebo IMUs of a URDF are take this name and a number
GAZEBO_SITE = "gyro_sim_gazebo_imu_"


def _gazebo_sites(spec: Any, gazebo: GazeboSensors) -> list[tuple[GazeboImu, str]]:
    """A site on each Gazebo IMU's link at its pose, so that MuJoCo's compiler carries it
    with the link wherever it fuses a fixed link into its parent; the IMUs with their sites'
    names."""
    out = []
    for i, imu in enumerate(gazebo.imus):
        body = spec.body(imu.link)
        if body is None:  # a link MuJoCo did not make a body of
            gazebo.notes.append(f"{imu.element}: not imported: MuJoCo has no body for the link")
            continue
        name, extra = f"{GAZEBO_SITE}{i}", 0
        while spec.site(name) is not None:
            extra += 1
            name = f"{GAZEBO_SITE}{i}_{extra}"
        body.add_site(name=name, pos=[float(x) for x in imu.position],
                      quat=[float(x) for x in imu.quaternion])
        out.append((imu, name))
    return out


#: the parent of a body hanging from the base (docs/scene-format.md)
BASE_PARENT = "base"
#: how much of a file's head is read to find its root element
HEAD_BYTES = 65536
_MARKUP = re.compile(r"<\?.*?\?>|<!--.*?-->|<!DOCTYPE[^>]*>", re.S)


def _kind(path: str) -> str:
    """"URDF" when the file's root element is ``<robot>`` (as MuJoCo decides), else "MJCF"."""
    with open(path, "rb") as stream:
        head = stream.read(HEAD_BYTES).decode("utf-8", "replace")
    root = re.search(r"<\s*([A-Za-z_][\w.-]*)", _MARKUP.sub("", head))
    return "URDF" if root is not None and root.group(1) == "robot" else "MJCF"


@dataclass
class _Group:
    """A moving body of the model with the bodies welded to it (one rigid body)."""

    root: int  # the body carrying the joint
    joint: int
    kind: str  # "free" | "ball" | "hinge"
    parent: int  # the root of the parent group (0: the world)
    members: list[int]
    mass: float = 0.0
    com: np.ndarray = field(default_factory=lambda: np.zeros(3))  # world, reference pose
    inertia: np.ndarray = field(default_factory=lambda: np.zeros((3, 3)))  # about com, world
    origin: np.ndarray = field(default_factory=lambda: np.zeros(3))  # O^k, world
    axis: np.ndarray = field(default_factory=lambda: np.zeros(3))  # hinge axis, world
    children: list[int] = field(default_factory=list)
    frame: bool = False  # a massless frame carrying one of its body's joints before the last


@dataclass
class _ImuSource:
    """The sensors of one site that make an IMU: how the file gives them."""

    site: int  # the site in the compiled model
    element: str  # how messages name it
    name: str  # the IMU's name before it is made unique
    rate: float | None = None  # Hz; None: every publication
    gyro_sigma: float = 0.0  # white noise, standard deviation per sample (rad/s)
    accel_sigma: float = 0.0  # (m/s^2)
    gyro_walk: float = 0.0  # bias random walk density (rad/s^2/sqrt(Hz))
    accel_walk: float = 0.0  # (m/s^3/sqrt(Hz))
    notes: list[str] = field(default_factory=list)  # what of it is left out, one line each


class _Importer:
    """One model's conversion: refusals first, then the tree, frames and initial state."""

    def __init__(self, mujoco: Any, model: Any, path: str, kind: str,
                 gazebo: GazeboSensors | None = None, gazebo_sites: Sequence[tuple[GazeboImu, str]] = ()):
        self.mj = mujoco
        self.m = model
        self.path = path
        self.kind = kind
        self.gazebo = gazebo
        self.gazebo_sites = list(gazebo_sites)
        self.errors: list[str] = []
        self.notes: list[str] = []
        self.friction: dict[int, dict[str, float]] = {}  # hinge joint -> its scene friction
        self.armature: dict[int, float] = {}  # hinge joint -> its armature (kg m^2)
        self.spring: dict[int, dict[str, float]] = {}  # hinge joint -> its scene spring
        self.servo: dict[int, dict[str, Any]] = {}  # hinge joint -> its scene servo (a model with servos)
        self.actfrc: dict[int, tuple[float, float]] = {}  # joint of one actuator -> its actuatorfrcrange
        self.max_torque: dict[int, float] = {}  # joint of one motor -> its actuatorfrcrange as max_torque
        self.locked: dict[str, float] = {}  # joints welded (gyro_sim.scene.mjcf._lock_joints)
        self.gear: float | None = None  # armatures as geared motors of this ratio (import_model)
        self._model_names: set[str] | None = None  # every joint's and body's name (`_unused`)

    # --- names
    def _name(self, obj: Any, index: int) -> str:
        return self.mj.mj_id2name(self.m, obj, index) or ""

    def body_name(self, b: int) -> str:
        return self._name(self.mj.mjtObj.mjOBJ_BODY, b)

    def joint_name(self, j: int) -> str:
        return self._name(self.mj.mjtObj.mjOBJ_JOINT, j)

    def body(self, b: int) -> str:
        name = self.body_name(b)
        return f"body {name!r}" if name else f"body #{b} (unnamed)"

    def joint(self, j: int, bare: bool = False) -> str:
        """How a message names joint `j`; an unnamed one by its number (and its body, unless
        `bare`: the message names the body already)."""
        name = self.joint_name(j)
        if name:
            return f"joint {name!r}"
        return f"joint #{j}" if bare else f"joint #{j} of {self.body(self.m.jnt_bodyid[j])}"

    def fail(self, element: str, why: str) -> None:
        self.errors.append(f"{self.path}: {element}: {why}")

    def raise_errors(self) -> None:
        if self.errors:
            raise ModelError(self.errors, self.path)

    # --- refusals
    def check_elements(self) -> None:
        mj, m = self.mj, self.m
        obj = mj.mjtObj
        flags = int(m.opt.disableflags)
        dsbl = mj.mjtDisableBit
        springs = not flags & int(dsbl.mjDSBL_SPRING)
        dampers = not flags & int(dsbl.mjDSBL_DAMPER)
        friction = not flags & int(dsbl.mjDSBL_FRICTIONLOSS)
        for t in range(m.ntendon):
            name = self._name(obj.mjOBJ_TENDON, t)
            wraps = range(int(m.tendon_adr[t]), int(m.tendon_adr[t]) + int(m.tendon_num[t]))
            joints = [int(m.wrap_objid[w]) for w in wraps if int(m.wrap_type[w]) == int(mj.mjtWrap.mjWRAP_JOINT)]
            hint = ""
            if joints and len(joints) == len(wraps) and all(self.lockable(j) for j in joints):
                hint = ("; --lock its joints (" + ", ".join(repr(self.joint_name(j)) for j in joints)
                        + ") to weld them: the tendon goes with them")
            self.fail(f"tendon {name!r}" if name else f"tendon #{t}",
                      "tendons are not supported (a tree of rigid bodies and rotors only)" + hint)
        if m.neq and not flags & int(dsbl.mjDSBL_EQUALITY):
            for e in range(m.neq):
                name = self._name(obj.mjOBJ_EQUALITY, e)
                if int(m.eq_type[e]) in (int(mj.mjtEq.mjEQ_CONNECT), int(mj.mjtEq.mjEQ_WELD)):
                    ends = [int(i) if int(m.eq_objtype[e]) != int(obj.mjOBJ_SITE) else int(m.site_bodyid[i])
                            for i in (m.eq_obj1id[e], m.eq_obj2id[e])]
                    if m.body_weldid[ends[0]] == m.body_weldid[ends[1]]:  # one rigid body: no force on it
                        by = " by --lock" if self.locked else ""
                        self.notes.append(f"{f'equality {name!r}' if name else f'equality #{e}'}: left out, "
                                          f"{self.body(ends[0])} and {self.body(ends[1])} are welded into "
                                          f"one{by} (it moves nothing)")
                        continue
                    loop = self.loop_joints(*ends)
                    self.fail(f"equality {name!r}" if name else f"equality #{e}",
                              f"equality constraints are not supported (an open tree only): it closes a loop "
                              f"from {self.body(ends[0])} to {self.body(ends[1])}"
                              + ("; --lock the joints of the loop to weld it (" + ", ".join(
                                  repr(self.joint_name(j)) for j in loop) + ")"
                                 if loop and all(self.lockable(j) for j in loop) else ""))
                    continue
                coupled = [int(j) for j in (m.eq_obj1id[e], m.eq_obj2id[e]) if j >= 0]
                lockable = int(m.eq_type[e]) == int(mj.mjtEq.mjEQ_JOINT) and all(self.lockable(j) for j in coupled)
                self.fail(f"equality {name!r}" if name else f"equality #{e}",
                          "equality constraints are not supported (an open tree only)"
                          + ("; --lock the joints it couples to weld them" if lockable else ""))
        for f in range(m.nflex):
            name = self._name(obj.mjOBJ_FLEX, f)
            self.fail(f"flex {name!r}" if name else f"flex #{f}",
                      "deformable bodies are not supported (rigid bodies only)")
        for i in range(m.nplugin):
            self.fail(f"plugin #{i}", "MuJoCo plugins are not supported (their forces are "
                                      "outside the equations of motion)")
        if m.opt.density != 0.0 or m.opt.viscosity != 0.0:
            self.fail("option", "density and viscosity (fluid forces) are not supported; "
                                "set them to 0")
        for b in range(1, m.nbody):
            if m.body_gravcomp[b] != 0.0:
                self.fail(self.body(b), "gravcomp (gravity compensation) is not supported")
            if m.body_jntnum[b] > 1:  # docs/models.md, "Several joints in one body"
                joints = range(int(m.body_jntadr[b]), int(m.body_jntadr[b]) + int(m.body_jntnum[b]))
                if any(int(m.jnt_type[j]) in (int(mj.mjtJoint.mjJNT_FREE), int(mj.mjtJoint.mjJNT_BALL))
                       for j in joints):
                    self.fail(self.body(b), f"{m.body_jntnum[b]} joints, a ball or free joint among them; "
                                            "several joints in one body are hinge and slide joints only")
        for j in range(m.njnt):
            kind = int(m.jnt_type[j])
            dofs = range(m.jnt_dofadr[j], m.jnt_dofadr[j] + (6 if kind == 0 else 3 if kind == 1 else 1))
            axis = kind in (int(mj.mjtJoint.mjJNT_HINGE), int(mj.mjtJoint.mjJNT_SLIDE))  # one coordinate
            if springs and np.any(getattr(m, "jnt_stiffnesspoly", np.zeros((m.njnt, 1)))[j]):
                self.fail(self.joint(j), "stiffnesspoly (a nonlinear spring) is not supported; a "
                                         "linear stiffness is")
            elif springs and m.jnt_stiffness[j] != 0.0:
                if axis:  # docs/models.md, "Armature and springs"
                    self.spring[j] = {"stiffness": _tidy(m.jnt_stiffness[j]),
                                      "reference": _tidy(m.qpos_spring[m.jnt_qposadr[j]])}
                else:
                    self.fail(self.joint(j), f"stiffness on a {('free', 'ball')[kind]} joint is not "
                                             "supported (a spring acts on a hinge's axis)")
            if dampers and np.any(getattr(m, "dof_dampingpoly", np.zeros((m.nv, 1)))[dofs]):
                self.fail(self.joint(j), "dampingpoly (a nonlinear damper) is not supported; "
                                         "a linear damping is")
            viscous = float(m.dof_damping[dofs][0]) if dampers else 0.0
            coulomb = float(m.dof_frictionloss[dofs][0]) if friction else 0.0
            if axis:
                if viscous or coulomb:  # the axis's friction (docs/models.md, "Damping and friction")
                    self.friction[j] = {key: _tidy(value) for key, value in
                                        (("coulomb", coulomb), ("viscous", viscous)) if value}
            elif dampers and np.any(m.dof_damping[dofs]):
                self.fail(self.joint(j), f"damping on a {('free', 'ball')[kind]} joint is not "
                                         "supported (friction acts on a hinge's or rotor's axis)")
            elif friction and np.any(m.dof_frictionloss[dofs]):
                self.fail(self.joint(j), f"frictionloss on a {('free', 'ball')[kind]} joint is "
                                         "not supported (friction acts on a hinge's or rotor's axis)")
            if np.any(m.dof_armature[dofs]):
                if axis:  # docs/models.md, "Armature and springs"
                    self.armature[j] = _tidy(m.dof_armature[dofs][0])
                else:
                    self.fail(self.joint(j), f"armature on a {('free', 'ball')[kind]} joint is not "
                                             "supported (a reflected inertia on a hinge's axis is)")
            if m.jnt_limited[j]:
                low, high = m.jnt_range[j]
                self.notes.append(f"{self.joint(j)}: limits [{low:g}, {high:g}] not enforced")
            if m.jnt_actfrclimited[j]:
                low, high = m.jnt_actfrcrange[j]
                drives = [a for a in range(m.nu) if int(m.actuator_trnid[a][0]) == j and int(m.actuator_trntype[a])
                          in (int(mj.mjtTrn.mjTRN_JOINT), int(mj.mjtTrn.mjTRN_JOINTINPARENT))]
                if len(drives) == 1 and m.actuator_gear[drives[0]][0] != 0.0:  # its actuator's bound
                    self.actfrc[j] = (float(low), float(high))  # (check_actuators, add_servo)
                else:
                    self.notes.append(f"{self.joint(j)}: actuatorfrcrange [{low:g}, {high:g}] not "
                                      "enforced" + (f" ({len(drives)} actuators drive it)" if drives else ""))
        self.check_actuators()

    def check_actuators(self) -> None:
        """Motors become commands (axis moments), unless an actuator of the model has an affine
        bias (a servo): then every actuator becomes its hinge's servo (docs/models.md, "Servo
        actuators"), each commanded by its control."""
        mj, m = self.mj, self.m
        trn_joint = (int(mj.mjtTrn.mjTRN_JOINT), int(mj.mjtTrn.mjTRN_JOINTINPARENT))
        affine = int(mj.mjtBias.mjBIAS_AFFINE)
        servos = any(int(m.actuator_biastype[a]) == affine for a in range(m.nu))
        for a in range(m.nu):
            name = self._name(mj.mjtObj.mjOBJ_ACTUATOR, a)
            what = f"actuator {name!r}" if name else f"actuator #{a}"
            trn = int(m.actuator_trntype[a])
            if trn not in trn_joint:
                self.fail(what, f"drives a {mj.mjtTrn(trn).name.removeprefix('mjTRN_').lower()}; "
                                "actuators on hinge and slide joints are supported (motors, position, "
                                "velocity and affine general servos)")
                continue
            if int(m.actuator_dyntype[a]) != int(mj.mjtDyn.mjDYN_NONE):
                self.fail(what, "activation dynamics are not supported (a motor only: "
                                "force = gain x ctrl)")
            if int(m.actuator_gaintype[a]) != int(mj.mjtGain.mjGAIN_FIXED) or \
                    int(m.actuator_biastype[a]) not in (int(mj.mjtBias.mjBIAS_NONE), affine):
                self.fail(what, "a variable gain or a muscle's bias is not supported; motors and "
                                "affine servos (force = gain x ctrl + b0 + b1 length + b2 velocity) are")
            for extra in ("actuator_damping", "actuator_armature", "actuator_delay"):
                if np.any(getattr(m, extra, np.zeros((m.nu, 1)))[a]):
                    self.fail(what, f"{extra.removeprefix('actuator_')} is not supported")
            j = int(m.actuator_trnid[a][0])
            if int(m.jnt_type[j]) != int(mj.mjtJoint.mjJNT_HINGE) and \
                    int(m.jnt_type[j]) != int(mj.mjtJoint.mjJNT_SLIDE):
                self.fail(what, f"drives the {('free', 'ball')[int(m.jnt_type[j])]} "
                                f"{self.joint(j)}; only hinges and slides take a commanded moment or force (a "
                                "spherical joint transmits none)")
            if servos:
                self.add_servo(a, what, j)
                continue
            if j in self.actfrc:  # its moment gear x gain x ctrl is clipped to it: max_torque when symmetric
                low, high = self.actfrc[j]
                if low == -high:
                    self.max_torque[j] = _tidy(high)
                else:
                    self.notes.append(f"{self.joint(j)}: actuatorfrcrange [{low:g}, {high:g}] not enforced "
                                      "(not symmetric: a max_torque bounds a moment on both sides alike)")
            if m.actuator_ctrllimited[a]:
                low, high = m.actuator_ctrlrange[a]
                self.notes.append(f"{what}: ctrlrange [{low:g}, {high:g}] not enforced")
            if m.actuator_forcelimited[a]:
                low, high = m.actuator_forcerange[a]
                self.notes.append(f"{what}: forcerange [{low:g}, {high:g}] not enforced")

    def add_servo(self, a: int, what: str, j: int) -> None:
        """Actuator `a` (on joint j) as its hinge's scene servo: MuJoCo's gainprm[0],
        biasprm[0:3], gear[0], ctrlrange and forcerange where limited."""
        m = self.m
        if j in self.servo:
            self.fail(what, f"drives {self.joint(j)}, which another actuator drives "
                            f"({self.servo[j].get('name') or 'unnamed'!r}); one servo per hinge is supported")
            return
        if int(m.jnt_type[j]) not in (int(self.mj.mjtJoint.mjJNT_HINGE), int(self.mj.mjtJoint.mjJNT_SLIDE)):
            return  # refused above
        servo: dict[str, Any] = {}
        name = self._name(self.mj.mjtObj.mjOBJ_ACTUATOR, a)
        if name:
            servo["name"] = name
        servo["gain"] = _tidy(m.actuator_gainprm[a][0])
        servo["bias"] = [_tidy(b) for b in m.actuator_biasprm[a][:3]]
        if m.actuator_gear[a][0] != 1.0:
            servo["gear"] = _tidy(m.actuator_gear[a][0])
        if m.actuator_ctrllimited[a]:
            servo["ctrl_range"] = [_tidy(v) for v in m.actuator_ctrlrange[a]]
        if m.actuator_forcelimited[a]:
            servo["force_range"] = [_tidy(v) for v in m.actuator_forcerange[a]]
        if j in self.actfrc:  # MuJoCo clips gear x force to the joint's range: the force to range / gear
            gear = float(m.actuator_gear[a][0])
            low, high = sorted(v / gear for v in self.actfrc[j])
            own = servo.get("force_range", [-math.inf, math.inf])
            servo["force_range"] = [_tidy(min(max(v, low), high)) for v in own]
        self.servo[j] = servo

    # --- structure
    def groups(self) -> dict[int, _Group]:
        mj, m = self.mj, self.m
        kinds = {int(mj.mjtJoint.mjJNT_FREE): "free", int(mj.mjtJoint.mjJNT_BALL): "ball",
                 int(mj.mjtJoint.mjJNT_HINGE): "hinge"}
        out: dict[int, _Group] = {}
        for b in range(1, m.nbody):
            if m.body_weldid[b] == b:
                j = int(m.body_jntadr[b])
                out[b] = _Group(root=b, joint=j, kind=kinds.get(int(m.jnt_type[j]), "slide"),
                                parent=int(m.body_weldid[m.body_parentid[b]]), members=[])
        static = []
        for b in range(1, m.nbody):
            weld = int(m.body_weldid[b])
            if weld == 0:
                static.append(b)
            else:
                out[weld].members.append(b)
                if weld != b:
                    self.notes.append(f"{self.body(b)}: no joint: merged into "
                                      f"{self.body(weld)}")
        if static:
            self.notes.append("static bodies (no joint, part of the base): "
                              + ", ".join(repr(self.body_name(b)) for b in static))
        for g in out.values():
            if g.parent:
                out[g.parent].children.append(g.root)
        # a body with several joints (docs/models.md, "Several joints in one body"): its group
        # carries the last joint; each joint before it is a massless frame, in MuJoCo's order
        self.frames: dict[int, list[_Group]] = {}
        for b, g in out.items():
            first, count = int(m.body_jntadr[b]), int(m.body_jntnum[b])
            if count > 1:
                kind = {j: kinds.get(int(m.jnt_type[j]), "slide") for j in range(first, first + count)}
                self.frames[b] = [_Group(root=b, joint=j, kind=kind[j], parent=g.parent, members=[], frame=True)
                                  for j in range(first, first + count - 1)]
                g.joint, g.kind = first + count - 1, kind[first + count - 1]
        return out

    def measure(self, groups: dict[int, _Group]) -> None:
        """Each group's mass, centre of mass, inertia and joint at the reference pose (qpos0 with
        every hinge and slide at 0: their coordinates are then MuJoCo's qpos, whatever their ref)."""
        mj, m = self.mj, self.m
        d = mj.MjData(m)  # qpos = qpos0
        one = (int(mj.mjtJoint.mjJNT_HINGE), int(mj.mjtJoint.mjJNT_SLIDE))
        d.qpos[[int(m.jnt_qposadr[j]) for j in range(m.njnt) if int(m.jnt_type[j]) in one]] = 0.0
        mj.mj_kinematics(m, d)
        self.R_ref = d.xmat.reshape(-1, 3, 3).copy()
        self.ximat_ref = d.ximat.reshape(-1, 3, 3).copy()
        self.site_pos_ref = d.site_xpos.reshape(-1, 3).copy()
        self.site_R_ref = d.site_xmat.reshape(-1, 3, 3).copy()
        for g in groups.values():
            masses = np.array([m.body_mass[b] for b in g.members])
            coms = np.array([d.xipos[b] for b in g.members])
            g.mass = float(masses.sum())
            g.com = masses @ coms / g.mass if g.mass > 0.0 else d.xipos[g.root].copy()
            inertia = np.zeros((3, 3))
            for mb, c, b in zip(masses, coms, g.members):
                R = d.ximat[b].reshape(3, 3)
                r = c - g.com
                inertia += R @ np.diag(m.body_inertia[b]) @ R.T + mb * ((r @ r) * np.eye(3) - np.outer(r, r))
            g.inertia = 0.5 * (inertia + inertia.T)
            g.origin = (d.xpos[g.root] if g.kind == "free" else d.xanchor[g.joint]).copy()
            g.axis = d.xaxis[g.joint].copy()
            for f in self.frames.get(g.root, []):  # massless: no mass, no inertia, the centre at O^k
                f.origin, f.axis = d.xanchor[f.joint].copy(), d.xaxis[f.joint].copy()
                f.com = f.origin.copy()

    def rotor_problem(self, g: _Group) -> str | None:
        """Why group `g` is no rotor of its parent, or None when it is one."""
        if g.kind != "hinge":
            return f"on a {g.kind} joint"
        if g.root in self.frames:
            return "it has several joints"
        if g.children:
            return "it carries moving bodies"
        if g.mass <= 0.0:
            return "massless"
        if g.joint in self.armature or g.joint in self.spring:
            return "its joint has armature or stiffness (a rotor's axis takes friction only)"
        if g.joint in self.servo:
            return "a servo drives its joint (a rotor's axis takes a commanded torque only)"
        a = g.axis / np.linalg.norm(g.axis)
        r = g.com - g.origin
        off = float(np.linalg.norm(r - (r @ a) * a))
        axial = float(a @ g.inertia @ a)
        transverse = 0.5 * (float(np.trace(g.inertia)) - axial)
        gyration = math.sqrt(max(axial, transverse) / g.mass)
        if off > ROTOR_RTOL * gyration:
            return (f"its centre of mass is {off:.3g} m off the hinge axis (at most "
                    f"{ROTOR_RTOL:g} x its radius of gyration {gyration:.3g} m)")
        symmetric = transverse * np.eye(3) + (axial - transverse) * np.outer(a, a)
        asymmetry = float(np.max(np.abs(g.inertia - symmetric))) / max(axial, transverse)
        if asymmetry > ROTOR_RTOL:
            return (f"its inertia is not symmetric about the hinge axis (relative asymmetry "
                    f"{asymmetry:.3g}, tolerance {ROTOR_RTOL:g})")
        return None

    def rotor_moments(self, r: _Group) -> tuple[float, float]:
        """A rotor's axial and transverse moments about its centre of mass: MuJoCo's principal
        moments when it is one body (the one whose axis is the hinge's, the mean of the other
        two), else those of its merged inertia."""
        a = r.axis / np.linalg.norm(r.axis)
        if len(r.members) == 1:
            b = r.members[0]
            principal = np.asarray(self.m.body_inertia[b], dtype=float)
            along = np.abs(self.ximat_ref[b].T @ a)
            i = int(np.argmax(along))
            others = np.delete(principal, i)
            return float(principal[i]), float(others.mean())
        axial = float(a @ r.inertia @ a)
        return axial, 0.5 * (float(np.trace(r.inertia)) - axial)

    def tree(self, groups: dict[int, _Group]) -> tuple[list[_Group], list[int], dict[int, list[_Group]]]:
        """The scene's bodies from the world outwards, every parent before its children (depth
        first, children in MuJoCo's order, so that a chain stays in its order and a body's first
        child follows it), each one's parent (its index in the list; -1: the base), and each
        body's rotors. A body with several joints is its massless frames, then itself."""
        top = [g for g in groups.values() if g.parent == 0]
        if not top:
            self.fail("worldbody", "no body has a joint: nothing moves")
            self.raise_errors()
        free = [g for g in top if g.kind == "free"]
        if free and len(top) > 1:
            others = [g for g in top if g is not free[0]]
            self.fail("worldbody", f"{len(others)} moving {'body hangs' if len(others) == 1 else 'bodies hang'} "
                      f"from the world (" + ", ".join(repr(self.body_name(g.root)) for g in others)
                      + f") beside the free {self.body(free[0].root)}: a free base carries the whole tree"
                      + self.weld_hint(groups, others, "weld them"))
        order: list[_Group] = []
        parents: list[int] = []
        rotors: dict[int, list[_Group]] = {}
        todo = [(g, -1) for g in reversed(top)]
        while todo:  # depth first, without recursion (a chain may be long)
            g, parent = todo.pop()
            if g.kind == "free" and parent >= 0:
                self.fail(self.joint(g.joint), "a free joint only on a body hanging from the world")
            for f in self.frames.get(g.root, []):
                order.append(f)
                parents.append(parent)
                parent = len(order) - 1
            order.append(g)
            parents.append(parent)
            kids = [groups[c] for c in g.children]
            rotors[g.root] = [c for c in kids if self.rotor_problem(c) is None]
            here = len(order) - 1
            todo += [(c, here) for c in reversed(kids) if c not in rotors[g.root]]
        return order, parents, rotors

    def loop_joints(self, a: int, b: int) -> list[int]:
        """The joints of the loop a connect or weld equality closes between bodies `a` and `b`:
        those of the bodies from each up to (not including) their nearest common ancestor, in
        the model's order."""
        m = self.m

        def chain(body: int) -> list[int]:
            out = [body]
            while body:
                body = int(m.body_parentid[body])
                out.append(body)
            return out

        up_a, up_b = chain(a), chain(b)
        common = next(x for x in up_a if x in up_b)
        bodies = up_a[:up_a.index(common)] + up_b[:up_b.index(common)]
        return sorted(j for x in bodies for j in range(int(m.body_jntadr[x]), int(m.body_jntadr[x])
                                                         + int(m.body_jntnum[x])))

    def lockable(self, j: int) -> bool:
        """Whether --lock welds joint `j` (_lock_joints): a named one."""
        return bool(self.joint_name(j))

    def weld_hint(self, groups: dict[int, _Group], parts: list[_Group], what: str) -> str:
        """How to weld the subtrees `parts` with --lock (`what`: the phrase it follows), naming
        their joints; or why --lock cannot (it is never suggested where it would be refused)."""
        m = self.m
        joints: list[int] = []
        todo = list(parts)
        while todo:
            g = todo.pop()
            for b in g.members:
                joints += range(int(m.body_jntadr[b]), int(m.body_jntadr[b]) + int(m.body_jntnum[b]))
            todo += [groups[c] for c in g.children]
        joints.sort()
        stuck = [j for j in joints if not self.lockable(j)]
        if stuck:
            return (f"; --lock cannot weld {', '.join(self.joint(j) for j in stuck[:5])}"
                    f"{' ...' if len(stuck) > 5 else ''} (only named joints are locked)")
        names = [self.joint_name(j) for j in joints]
        shown = ", ".join(repr(n) for n in names[:8]) + (" ..." if len(names) > 8 else "")
        return f"; {what} with --lock JOINT (their joints: {shown})"

    def scene_name(self, g: _Group, as_hinge: bool) -> str:
        """The scene name of a group (module docstring): joint first for hinges, slides and rotors;
        an unnamed joint of a body with several joints ``<body>_joint<i>`` (i its place in the
        body), with ``_`` added until it is no name of the model's. The name `base` is the
        scene's own (a `parent` naming it is the base): a body or joint of that name takes its
        other name, else ``base_`` (``_`` added likewise)."""
        joint, body = self.joint_name(g.joint), self.body_name(g.root)
        if not joint and g.root in self.frames:
            joint = self._unused(f"{body or f'body{g.root}'}_joint{g.joint - int(self.m.body_jntadr[g.root])}")
        first = (joint, body) if as_hinge else (body, joint)
        name = next((n for n in first if n and n != BASE_PARENT), "")
        if not name and BASE_PARENT in first:
            name = self._unused(BASE_PARENT + "_")
        return name or (f"joint{g.joint}" if as_hinge else f"body{g.root}")

    def _unused(self, name: str) -> str:
        """`name` with ``_`` added until it is no joint's or body's name in the model."""
        if self._model_names is None:
            m, obj = self.m, self.mj.mjtObj
            self._model_names = ({self._name(obj.mjOBJ_JOINT, j) for j in range(m.njnt)}
                                 | {self._name(obj.mjOBJ_BODY, b) for b in range(m.nbody)})
        while name in self._model_names:
            name += "_"
        return name

    # --- the scene
    def run(self, keyframe: str | None) -> ImportedModel:
        self.check_elements()
        if self.gazebo is not None:
            for element, why in self.gazebo.errors:
                self.fail(element, why)
        # the structure is checked too before anything is refused: one refusal says it all
        groups = self.groups()
        self.measure(groups)
        order, parents, rotors = self.tree(groups)
        self.raise_errors()
        key, key_name = self.keyframe(keyframe)
        self.raise_errors()
        state = self.initial_state(key)
        commands = self.commands(order, rotors)
        self.raise_errors()
        m, mj = self.m, self.mj
        actuated = {c.axis for c in commands}
        names, where, bodies = [], {}, []
        frames: dict[int, tuple[str, np.ndarray, np.ndarray]] = {}  # group root -> name, G, O^k
        scene_names, rotations = [], []  # by body: its scene name, its frame's rotation G at the reference pose
        first_child = {p: k for k, p in reversed(list(enumerate(parents)))}  # body (-1: the base) -> its first child
        for k, g in enumerate(order):
            name = self.scene_name(g, g.kind in ("hinge", "slide"))
            p = parents[k]
            G_parent = rotations[p] if p >= 0 else np.eye(3)
            G = self.R_ref[g.root] if g.kind in ("free", "ball") else G_parent
            frames[g.root] = (name, G, g.origin)
            scene_names.append(name)
            rotations.append(G)
            body: dict[str, Any] = {"name": name}
            if p != k - 1:  # not its parent's first child, which follows it (docs/scene-format.md, trees)
                body["parent"] = scene_names[p] if p >= 0 else BASE_PARENT
            if g.kind in ("hinge", "slide"):  # a slide keeps its parent's frame, as a hinge at angle 0
                body["joint"] = {"type": g.kind, "axis": _vec(G_parent.T @ g.axis)}
                if g.joint in self.friction:
                    body["joint"]["friction"] = self.friction[g.joint]
                if g.joint in self.armature and self.gear is None:
                    body["joint"]["armature"] = self.armature[g.joint]
                elif g.joint in self.armature and g.kind == "slide":  # a slide's drive stays its armature
                    body["joint"]["armature"] = self.armature[g.joint]
                    self.notes.append(f"joint {self.joint_name(g.joint)!r}: a slide's armature "
                                      f"{self.armature[g.joint]:g} kept (geared motors turn hinges)")
                elif g.joint in self.armature:  # the geared motor the armature reflects, on the parent
                    body["joint"]["motor"] = {"inertia": _tidy(self.armature[g.joint] / self.gear ** 2),
                                              "gear": _tidy(self.gear)}
                    on = ("on the base (which does not turn: exactly the armature)" if p < 0 else
                          "on its parent (its rotor's axial inertia joins the parent's)")
                    self.notes.append(f"joint {self.joint_name(g.joint)!r}: armature "
                                      f"{self.armature[g.joint]:g} as a geared motor of gear {self.gear:g} {on}")
                if g.joint in self.spring:
                    body["joint"]["spring"] = self.spring[g.joint]
                if g.joint in self.servo:
                    body["joint"]["servo"] = self.servo[g.joint]
                if g.joint in self.max_torque:
                    body["joint"]["max_torque"] = self.max_torque[g.joint]
            else:
                body["joint"] = {"type": "spherical"}
            if p != k - 1:  # its joint point O^k in the parent's frame, from the parent's O (after the axis)
                at = _vec(G_parent.T @ (g.origin - (order[p].origin if p >= 0 else order[0].origin)))
                joint = list(body["joint"].items())
                body["joint"] = dict(joint[:2] + [("at", at)] + joint[2:])
            body["mass"] = _tidy(g.mass)
            body["com"] = _vec(G.T @ (g.com - g.origin))
            body["inertia_com"] = _mat(G.T @ g.inertia @ G)
            if k in first_child:  # to its first child's joint point; the others say theirs (joint.at)
                body["next_joint"] = _vec(G.T @ (order[first_child[k]].origin - g.origin))
            element = f"{self.body(g.root)} ({g.kind} {self.joint(g.joint, bare=True)})"
            if g.frame:
                element = element[:-1] + ", a massless frame)"
            where[f"bodies[{k}]"] = element
            names.append((element, name))
            body_rotors = []
            for i, r in enumerate(rotors[g.root] if not g.frame else []):  # on the body's last frame
                rname = self.scene_name(r, True)
                a = r.axis / np.linalg.norm(r.axis)
                axial, transverse = self.rotor_moments(r)
                body_rotors.append({
                    "name": rname, "axis": _vec(G.T @ a), "position": _vec(G.T @ (r.com - g.origin)),
                    "mass": _tidy(r.mass), "axial_inertia": _tidy(axial),
                    "transverse_inertia": _tidy(transverse),
                    "mode": "torque", "spin": _tidy(state["spin"][r.root]),
                    "actuated": self.kind == "URDF" or rname in actuated,
                })
                if r.joint in self.friction:
                    body_rotors[-1]["friction"] = self.friction[r.joint]
                if r.joint in self.max_torque:
                    body_rotors[-1]["max_torque"] = self.max_torque[r.joint]
                if state["angle"][r.root] != 0.0:
                    self.notes.append(f"{self.joint(r.joint)}: the keyframe's angle "
                                      f"{state['angle'][r.root]:g} not kept (a rotor's angle "
                                      "starts at 0; a balanced rotor's angle changes nothing)")
                element = f"{self.body(r.root)} (rotor on {self.joint(r.joint, bare=True)})"
                where[f"bodies[{k}].rotors[{i}]"] = element
                names.append((element, rname))
            if body_rotors:
                body["rotors"] = body_rotors
            body["initial"] = state["frames"][g.joint] if g.frame else state["initial"][g.root]
            bodies.append(body)
        first = order[0]
        if first.kind == "free":
            base = {"type": "free", "position": _vec(state["position"]),
                    "velocity": _vec(state["velocity"])}
            where["base"] = f"{self.joint(first.joint)} (the free base)"
        else:
            base = {"type": "fixed", "position": _vec(first.origin)}
            where["base"] = f"{self.joint(first.joint)} (the fixed base)"
        mapping: dict[str, Any] = {"name": self.model_name()}
        gravity = np.asarray(m.opt.gravity, dtype=float)
        if not int(m.opt.disableflags) & int(mj.mjtDisableBit.mjDSBL_GRAVITY) and np.any(gravity):
            mapping["gravity"] = _vec(gravity)
            where["gravity"] = "option gravity"
        mapping["base"] = base
        mapping["bodies"] = bodies
        rotor_joints = {r.root: r.joint for rs in rotors.values() for r in rs}
        imus = self.imus(frames, rotor_joints, names, where)
        if imus:
            mapping["imus"] = imus
        if m.ngeom and not int(m.opt.disableflags) & int(mj.mjtDisableBit.mjDSBL_CONTACT):
            self.notes.insert(0, "contacts: ignored (no contacts in gyro_sim)")
        robot = None
        if self.kind == "URDF":  # the robot's own description and its links on the scene's bodies
            with open(self.path, encoding="utf-8") as stream:
                text = stream.read()
            body_frames = {name: (G, origin) for name, G, origin in frames.values()}
            rotor_axes = {self.scene_name(r, True): (frames[g.root][0], r.axis / np.linalg.norm(r.axis), r.origin)
                          for g in order for r in rotors[g.root]}
            try:
                robot = describe_robot(text, self.locked, body_frames, rotor_axes)
            except (ValueError, TypeError, KeyError, AttributeError, ET.ParseError) as exc:  # MuJoCo read it
                self.notes.append(f"robot description not kept (ROS gets the scene's): {exc}")
        return ImportedModel(mapping=mapping, path=self.path, kind=self.kind, keyframe=key_name,
                             names=tuple(names), commands=tuple(commands),
                             notes=tuple(self.notes), where=where, robot=robot)

    # --- sensors
    def sensor(self, s: int) -> str:
        """How messages name sensor `s`: its type and name (or number)."""
        kind = self.mj.mjtSensor(int(self.m.sensor_type[s])).name.removeprefix("mjSENS_").lower()
        name = self._name(self.mj.mjtObj.mjOBJ_SENSOR, s)
        return f"{kind} {name!r}" if name else f"{kind} #{s}"

    def site(self, i: int) -> str:
        name = self._name(self.mj.mjtObj.mjOBJ_SITE, i)
        return f"site {name!r}" if name else f"site #{i} (unnamed)"

    def mjcf_imus(self) -> list[_ImuSource]:
        """The MJCF sensors that make IMUs, one per site (docs/models.md, "Sensors"): a gyro
        or an accelerometer makes one; a framequat or framelinacc of the same site in the world
        frame joins it. The other sensors are listed in one note."""
        mj, m = self.mj, self.m
        kinds = mj.mjtSensor
        makes = {int(kinds.mjSENS_GYRO), int(kinds.mjSENS_ACCELEROMETER)}
        joins = {int(kinds.mjSENS_FRAMEQUAT), int(kinds.mjSENS_FRAMELINACC)}
        on_site = int(mj.mjtObj.mjOBJ_SITE)
        world = int(mj.mjtObj.mjOBJ_UNKNOWN)  # no reference frame: the world's
        by_site: dict[int, list[int]] = {}
        joining: dict[int, list[int]] = {}
        skipped: list[int] = []
        for s in range(m.nsensor):
            kind, site = int(m.sensor_type[s]), int(m.sensor_objid[s])
            if kind in makes:
                by_site.setdefault(site, []).append(s)
            elif kind in joins and int(m.sensor_objtype[s]) == on_site and int(m.sensor_reftype[s]) == world:
                joining.setdefault(site, []).append(s)
            else:
                skipped.append(s)
        for site, sensors in joining.items():
            if site in by_site:
                by_site[site] += sensors
            else:
                skipped += sensors
        if skipped:
            self.notes.append("sensors not imported (an IMU is a gyro or an accelerometer on a site): "
                              + ", ".join(self.sensor(s) for s in sorted(skipped)))
        return [self.mjcf_imu(site, sorted(sensors)) for site, sensors in sorted(by_site.items())]

    def mjcf_imu(self, site: int, sensors: list[int]) -> _ImuSource:
        """The IMU of one site's sensors: its name, rate (MuJoCo's ``interval``) and noise."""
        mj, m = self.mj, self.m
        kinds = mj.mjtSensor
        kind = {s: int(m.sensor_type[s]) for s in sensors}
        gyros = [s for s in sensors if kind[s] == int(kinds.mjSENS_GYRO)]
        accels = [s for s in sensors if kind[s] == int(kinds.mjSENS_ACCELEROMETER)]
        element = f"{self.site(site)} ({', '.join(self.sensor(s) for s in sensors)})"
        name = self._name(mj.mjtObj.mjOBJ_SITE, site)  # MJCF sensors name their sites
        source = _ImuSource(site=site, element=element, name=name)
        periods = [float(m.sensor_interval[s][0]) for s in gyros + accels]
        if all(p > 0.0 for p in periods):  # else one is computed every step: the fastest
            source.rate = _tidy(1.0 / min(periods))
        if len(set(periods)) > 1:
            source.notes.append("its sensors' intervals differ ("
                                + ", ".join(f"{p:g} s" for p in periods) + "): the IMU samples at "
                                + (f"{source.rate:g} Hz" if source.rate else "every publication"))
        if any(float(m.sensor_interval[s][1]) != 0.0 for s in sensors):
            source.notes.append("interval phase not kept (sample i is at time i / rate)")
        for s in sensors:
            if float(m.sensor_delay[s]) > 0.0:
                source.notes.append(f"{self.sensor(s)}: delay {float(m.sensor_delay[s]):g} s not "
                                    "modelled (the IMU reads the present state)")
            if float(m.sensor_cutoff[s]) > 0.0:
                source.notes.append(f"{self.sensor(s)}: cutoff {float(m.sensor_cutoff[s]):g} not "
                                    "enforced")
            if kind[s] == int(kinds.mjSENS_FRAMELINACC):
                source.notes.append(f"{self.sensor(s)}: given by the IMU in its own frame (the world "
                                    "frame's is its orientation times its linear_acceleration)")
            if s not in gyros + accels and float(m.sensor_noise[s]) > 0.0:
                source.notes.append(f"{self.sensor(s)}: noise not modelled (an IMU's orientation and "
                                    "world-frame acceleration have none)")
        source.gyro_sigma = max((float(m.sensor_noise[s]) for s in gyros), default=0.0)
        source.accel_sigma = max((float(m.sensor_noise[s]) for s in accels), default=0.0)
        return source

    def gazebo_imus(self) -> list[_ImuSource]:
        """The IMUs of a URDF's ``<gazebo>`` sensors (gyro_sim.scene.gazebo), on their sites."""
        gazebo = self.gazebo
        if gazebo is None:
            return []
        if gazebo.skipped:
            self.notes.append("gazebo sensors not imported (IMUs only): " + ", ".join(gazebo.skipped))
        self.notes += gazebo.notes
        out = []
        for imu, site_name in self.gazebo_sites:
            site = self.mj.mj_name2id(self.m, self.mj.mjtObj.mjOBJ_SITE, site_name)
            source = _ImuSource(site=site, element=imu.element, name=imu.name, rate=imu.rate,
                                gyro_sigma=imu.gyro.stddev, accel_sigma=imu.accel.stddev,
                                gyro_walk=imu.gyro.walk, accel_walk=imu.accel.walk, notes=list(imu.notes))
            for what, noise in (("gyro", imu.gyro), ("accelerometer", imu.accel)):
                if noise.walk > 0.0:
                    source.notes.append(f"{what} dynamic bias: correlation time "
                                        f"{noise.correlation_time:g} s not kept (the bias walks "
                                        "without decay: the same for times short against it)")
            out.append(source)
        return out

    def imus(self, frames: dict[int, tuple[str, np.ndarray, np.ndarray]], rotor_joints: dict[int, int],
             names: list, where: dict) -> list[dict]:
        """The scene's `imus` from the model's sensors (docs/models.md, "Sensors"): each on the
        scene body its site moves with, at the site's pose in that body's frame at the
        reference pose; the noise per sample converted to densities at its rate. What cannot
        be an IMU is said in the notes; `names` and `where` gain the IMUs."""

        m = self.m
        taken = {frame[0] for frame in frames.values()}
        out = []
        for source in self.mjcf_imus() + self.gazebo_imus():
            notes = list(dict.fromkeys(source.notes))
            body = int(m.site_bodyid[source.site])
            root = int(m.body_weldid[body])
            if root == 0:
                on = "the world body" if body == 0 else f"the static {self.body(body)} (part of the base)"
                self.notes.append(f"{source.element}: not imported: on {on}; an IMU is fixed to a "
                                  "moving body")
                continue
            if root in rotor_joints:
                self.notes.append(f"{source.element}: not imported: on the rotor of "
                                  f"{self.joint(rotor_joints[root])}, which is no body of the scene")
                continue
            body_name, G, origin = frames[root]
            name = source.name
            if name in taken:
                base, extra = f"{name}_imu", 1
                name = base
                while name in taken:
                    extra += 1
                    name = f"{base}{extra}"
                notes.append(f"named {name!r}: {source.name!r} is a body's or another IMU's name")
            taken.add(name)
            imu: dict[str, Any] = {
                "name": name, "body": body_name,
                "position": _vec(G.T @ (self.site_pos_ref[source.site] - origin)),
                "orientation": _vec(matrix_to_quat(G.T @ self.site_R_ref[source.site])),
            }
            rate = source.rate
            if rate is not None:
                imu["rate"] = rate
                if not divides(rate, DEFAULT_IMU_RATE):
                    notes.append(f"rate {rate:g} Hz kept: publications at the default "
                                 f"{DEFAULT_IMU_RATE:g} Hz cannot sample it (publish at a multiple "
                                 f"of {rate:g} Hz)")
            per_second = rate if rate is not None else DEFAULT_IMU_RATE
            noise = {"gyro_noise_density": source.gyro_sigma / math.sqrt(per_second),
                     "gyro_bias_instability": source.gyro_walk,
                     "accel_noise_density": source.accel_sigma / math.sqrt(per_second),
                     "accel_bias_instability": source.accel_walk}
            if rate is None and (source.gyro_sigma or source.accel_sigma):
                notes.append(f"no rate: the noise per sample is the model's at {DEFAULT_IMU_RATE:g} Hz, "
                             "the default publish rate (the density is what is kept)")
            imu.update({key: _tidy(value) for key, value in noise.items() if value})
            if any(noise.values()):
                imu["seed"] = len(out)
            self.notes += [f"{source.element}: {note}" for note in notes]
            where[f"imus[{len(out)}]"] = source.element
            names.append((source.element, name))
            out.append(imu)
        return out

    def model_name(self) -> str:
        """The scene's title: the model's name (the first of MuJoCo's names), kind and file."""
        text = bytes(self.m.names).split(b"\0", 1)[0].decode("utf-8", "replace")
        name = text.strip() or os.path.splitext(os.path.basename(self.path))[0]
        return f"{name} ({self.kind} {os.path.basename(self.path)})"

    def keyframe(self, keyframe: str | None) -> tuple[int | None, str | None]:
        m, mj = self.m, self.mj
        names = [self._name(mj.mjtObj.mjOBJ_KEY, k) for k in range(m.nkey)]
        if keyframe is None:
            return (0, names[0]) if m.nkey else (None, None)
        if keyframe == "none" and keyframe not in names:  # the reference pose at rest (--keyframe none)
            return None, None
        if keyframe not in names or not keyframe:
            known = ", ".join(repr(n) for n in names if n) or "none named"
            self.fail(f"keyframe {keyframe!r}", f"no such keyframe (the model's: {known})")
            return None, None
        return names.index(keyframe), keyframe

    def initial_state(self, key: int | None) -> dict:
        """Joint states from keyframe `key` (None: rest at the reference pose), by group root:
        ball and free bodies' quaternions and body-frame angular velocities, hinge angles and
        rates, rotor spins p = omega . e + kappa' (eqs (18)-(19)), the free base's O^1 and its
        velocity, from MuJoCo's kinematics."""
        mj, m = self.mj, self.m
        d = mj.MjData(m)
        if key is None:
            mj.mj_resetData(m, d)
        else:
            mj.mj_resetDataKeyframe(m, d, key)
            if m.key_time[key] != 0.0:
                self.notes.append(f"keyframe: time {m.key_time[key]:g} not kept (the scene "
                                  "starts at t = 0)")
            if m.nu and self.servo:  # the servos' initial controls (docs/models.md, "Servo actuators")
                for a in range(m.nu):
                    j = int(m.actuator_trnid[a][0])
                    if j in self.servo and m.key_ctrl[key][a] != 0.0:
                        self.servo[j]["control"] = _tidy(m.key_ctrl[key][a])
                apart = []  # position servos whose target (where their force is 0 at rest) is not the pose
                for a in range(m.nu):
                    j = int(m.actuator_trnid[a][0])
                    b1, gear = float(m.actuator_biasprm[a][1]), float(m.actuator_gear[a][0])
                    if j not in self.servo or b1 == 0.0 or gear == 0.0:
                        continue
                    ctrl = float(m.key_ctrl[key][a])
                    if m.actuator_ctrllimited[a]:
                        ctrl = min(max(ctrl, float(m.actuator_ctrlrange[a][0])), float(m.actuator_ctrlrange[a][1]))
                    target = -(float(m.actuator_gainprm[a][0]) * ctrl + float(m.actuator_biasprm[a][0])) / (b1 * gear)
                    pose = float(m.key_qpos[key][m.jnt_qposadr[j]])
                    if abs(target - pose) > 1e-6 * max(1.0, abs(pose)):
                        unit = "m" if int(m.jnt_type[j]) == int(mj.mjtJoint.mjJNT_SLIDE) else "rad"
                        apart.append(f"{self.servo[j].get('name') or self.joint_name(j)!r} target {target:.6g}, "
                                     f"pose {pose:.6g} ({target - pose:+.3g} {unit})")
                if apart:
                    self.notes.append(f"keyframe {self._name(mj.mjtObj.mjOBJ_KEY, key) or key!r}: its ctrl is "
                                      f"not its pose, the servos pull away from it at t = 0: " + "; ".join(apart))
            elif m.nu and np.any(m.key_ctrl[key]):
                self.notes.append("keyframe: ctrl not kept (commands are given to the simulator as "
                                  "axis moments)")
        mj.mj_kinematics(m, d)
        mj.mj_comPos(m, d)
        mj.mj_comVel(m, d)
        out: dict[str, Any] = {"initial": {}, "spin": {}, "angle": {}, "frames": {}}
        omega: dict[int, np.ndarray] = {}
        vel = np.zeros(6)
        for b in range(1, m.nbody):
            if m.body_weldid[b] != b:
                continue
            mj.mj_objectVelocity(m, d, mj.mjtObj.mjOBJ_XBODY, b, vel, 0)
            omega[b] = vel[:3].copy()
            j = int(m.body_jntadr[b]) + int(m.body_jntnum[b]) - 1  # the body's last joint (its group's)
            for f in range(int(m.body_jntadr[b]), j):  # the massless frames' joints before it
                slide = int(m.jnt_type[f]) == int(mj.mjtJoint.mjJNT_SLIDE)
                keys = ("position", "velocity") if slide else ("angle", "rate")
                out["frames"][f] = dict(zip(keys, (_tidy(d.qpos[m.jnt_qposadr[f]]), _tidy(d.qvel[m.jnt_dofadr[f]]))))
            kind = int(m.jnt_type[j])
            R = d.xmat[b].reshape(3, 3)
            if kind in (int(mj.mjtJoint.mjJNT_FREE), int(mj.mjtJoint.mjJNT_BALL)):
                q = d.xquat[b] / np.linalg.norm(d.xquat[b])
                out["initial"][b] = {"quaternion": _vec(q), "angular_velocity": _vec(R.T @ vel[:3])}
                if kind == int(mj.mjtJoint.mjJNT_FREE):
                    out["position"] = d.xpos[b].copy()
                    out["velocity"] = vel[3:].copy()
            elif kind == int(mj.mjtJoint.mjJNT_SLIDE):
                out["initial"][b] = {"position": _tidy(d.qpos[m.jnt_qposadr[j]]),
                                     "velocity": _tidy(d.qvel[m.jnt_dofadr[j]])}
            else:
                out["initial"][b] = {"angle": _tidy(d.qpos[m.jnt_qposadr[j]]),
                                     "rate": _tidy(d.qvel[m.jnt_dofadr[j]])}
                parent = int(m.body_weldid[m.body_parentid[b]])
                if parent:  # should this body be a rotor: its absolute spin (eqs (18)-(19))
                    axis = d.xaxis[j] / np.linalg.norm(d.xaxis[j])
                    out["spin"][b] = float(omega[parent] @ axis) + float(d.qvel[m.jnt_dofadr[j]])
                    out["angle"][b] = float(d.qpos[m.jnt_qposadr[j]])
        return out

    def commands(self, order: list[_Group], rotors: dict[int, list[_Group]]) -> list[Command]:
        """Each actuator's axis and factor (gear x gain)."""
        mj, m = self.mj, self.m
        axis_of = {}
        for g in order:
            if g.kind in ("hinge", "slide"):
                axis_of[g.joint] = self.scene_name(g, True)
            for r in rotors[g.root]:
                axis_of[r.joint] = self.scene_name(r, True)
        out = []
        for a in range(m.nu if not self.servo else 0):  # servos are commanded by their controls
            j = int(m.actuator_trnid[a][0])
            name = self._name(mj.mjtObj.mjOBJ_ACTUATOR, a) or f"actuator{a}"
            out.append(Command(actuator=name, axis=axis_of[j],
                               factor=_tidy(m.actuator_gear[a][0] * m.actuator_gainprm[a][0])))
        return out


# ----------------------------------------------------------------------------- writing
def scene_yaml(imported: ImportedModel) -> str:
    """The scene of `imported` as YAML text: a comment naming the source, the names, how
    MuJoCo's controls map onto the axis moments and the notes (what was left out or
    approximated), then the scene
    (numbers as Python's repr: they read back exactly)."""
    import yaml

    source = os.path.basename(imported.path)
    key = ("the reference pose at rest" if imported.keyframe is None
           else f"keyframe {imported.keyframe!r}" if imported.keyframe else "the first keyframe")
    lines = [f"# gyro_sim scene imported by gyro-sim import from {source} ({imported.kind}), "
             f"initial state from {key}.",
             "# Names: a hinge, slide or rotor is named after its joint, a ball or free body after its "
             "body, an IMU after its site or Gazebo sensor (docs/models.md)."]
    lines += [f"#   {element} -> {name}" for element, name in imported.names]
    if imported.commands:
        lines.append("# Commands: the axis moment is gear x gain x ctrl of the actuator:")
        lines += [f"#   {c.actuator} -> axis {c.axis}: moment = {c.factor!r} x ctrl"
                  for c in imported.commands]
    servos = [(b["joint"]["servo"].get("name", b["name"]), b["name"]) for b in imported.mapping["bodies"]
              if "servo" in b["joint"]]
    if servos:
        lines.append("# Controls (Simulator.set_controls, ~/joint_commands by joint): each actuator is its "
                     "joint's servo:")
        lines += [f"#   {actuator} -> joint {joint}" for actuator, joint in servos]
    if imported.notes:
        lines.append("# Notes (left out or approximated):")
        lines += [f"#   {note}" for note in imported.notes]
    body = yaml.safe_dump(imported.mapping, sort_keys=False, default_flow_style=None, width=100,
                          allow_unicode=True)
    return "\n".join(lines) + "\n" + body
