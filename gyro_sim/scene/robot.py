"""A URDF robot as itself: its own description and its links' frames (docs/models.md, "ROS
sees the robot as itself").

A scene imported from a URDF keeps the robot's URDF (locked joints written as ``fixed`` at
their values, everything else as the file gives it: link and joint names, mesh URIs) and, for
every link, where its frame sits on the scene body it moves with. The node publishes that
URDF on ``robot_description`` and each link's pose on ``/tf`` by the link's name, so RViz or
Foxglove draw the robot from them as they do from Gazebo's ground truth.

Frames. A hinge body's scene frame has its origin at the joint point O^k (the URDF joint's
origin, where the child link's frame is) and turns with the hinge from its parent's frame at
the reference pose (docs/scene-format.md); the URDF link frame of the joint's child sits at
the same point, turned by the joint's ``rpy``. A link's frame is thus a constant pose in its
body's frame: ``world_T_link = world_T_body(t) body_T_link``, measured at the reference pose
(every joint at 0, locked ones at their values). A link on a fixed joint rides on its parent's
body; a link of a rotor turns with the rotor's angle about the rotor's axis on its carrier; a
link on no moving joint (the root) is fixed in the world.
"""
from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from gyro_sim.dynamics.rotations import axis_angle_matrix, matrix_to_quat, quat_to_matrix
from gyro_sim.scene.gazebo import rpy_quaternion

__all__ = ["LinkFrame", "RobotDescription", "describe_robot", "link_poses", "link_transforms"]

#: URDF joint types that move (a locked one is written fixed)
MOVING = ("revolute", "continuous", "prismatic", "floating", "planar")


@dataclass(frozen=True, eq=False)
class LinkFrame:
    """Where one URDF link's frame is on the scene."""

    name: str
    body: str | None  # the scene body it moves with; None: fixed in the world
    rotor: str | None  # the rotor (of `body`) it turns with
    position: np.ndarray  # (3,) the link's origin in the body's frame (from O^k), rotor angle 0
    rotation: np.ndarray  # (3, 3) body_R_link at rotor angle 0
    axis: np.ndarray | None = None  # a rotor's unit axis, body frame
    anchor: np.ndarray | None = None  # a point of a rotor's axis, body frame (from O^k)


@dataclass(frozen=True, eq=False)
class RobotDescription:
    """A URDF robot's own description and its links' frames on the scene."""

    urdf: str  # the robot's URDF, locked joints fixed
    links: tuple[LinkFrame, ...]


def _origin(joint: ET.Element) -> tuple[np.ndarray, np.ndarray]:
    """A joint's <origin>: (xyz, R)."""
    origin = joint.find("origin")
    xyz = np.zeros(3)
    rpy = np.zeros(3)
    if origin is not None:
        xyz = np.array([float(v) for v in (origin.get("xyz") or "0 0 0").split()])
        rpy = np.array([float(v) for v in (origin.get("rpy") or "0 0 0").split()])
    return xyz, quat_to_matrix(np.asarray(rpy_quaternion(rpy), dtype=float))


def _axis(joint: ET.Element) -> np.ndarray:
    axis = joint.find("axis")
    a = np.array([float(v) for v in (axis.get("xyz") if axis is not None else "1 0 0").split()])
    return a / np.linalg.norm(a)


def _motion(joint: ET.Element, value: float) -> tuple[np.ndarray, np.ndarray]:
    """The child's displacement in the joint frame at `value`: (translation, rotation)."""
    if joint.get("type") == "prismatic":
        return value * _axis(joint), np.eye(3)
    return np.zeros(3), axis_angle_matrix(_axis(joint), value)


def _reference(root: ET.Element, locked: Mapping[str, float]) -> tuple[dict, dict, str]:
    """Every link's world pose (position, rotation) at the reference pose (joints at 0, locked
    ones at their values, the root link at the world origin); joints by child link; the root."""
    joints = {j.find("child").get("link"): j for j in root.findall("joint")}
    links = [link.get("name") for link in root.findall("link")]
    roots = [name for name in links if name not in joints]
    poses: dict[str, tuple[np.ndarray, np.ndarray]] = {name: (np.zeros(3), np.eye(3)) for name in roots}

    def pose(name: str) -> tuple[np.ndarray, np.ndarray]:
        if name not in poses:
            joint = joints[name]
            p, R = pose(joint.find("parent").get("link"))
            xyz, Ro = _origin(joint)
            if joint.get("name") in locked:  # every other joint at 0: no motion (a fixed joint may have no axis)
                t, Rm = _motion(joint, locked[joint.get("name")])
                xyz, Ro = xyz + Ro @ t, Ro @ Rm
            poses[name] = (p + R @ xyz, R @ Ro)
        return poses[name]

    for name in links:
        pose(name)
    return poses, joints, roots[0] if roots else ""


def describe_robot(text: str, locked: Mapping[str, float], bodies: Mapping[str, tuple[np.ndarray, np.ndarray]],
                   rotors: Mapping[str, tuple[str, np.ndarray, np.ndarray]]) -> RobotDescription:
    """The description of a URDF robot imported as a scene.

    text : the URDF
    locked : the locked joints and their values
    bodies : scene body name (the name of its joint) -> (G, O): its frame's rotation and
        origin in the world at the reference pose
    rotors : rotor name (its joint's) -> (carrier body, unit axis, a point of the axis), world,
        at the reference pose
    """
    root = ET.fromstring(text)
    poses, joints, _ = _reference(root, locked)
    frames = []
    for link in root.findall("link"):
        name = link.get("name")
        owner = name
        body = rotor = None
        while owner in joints:  # up to the first moving, unlocked joint
            joint = joints[owner]
            jname = joint.get("name")
            if joint.get("type") in MOVING and jname not in locked:
                if jname in rotors:
                    rotor, body = jname, rotors[jname][0]
                elif jname in bodies:
                    body = jname
                break
            owner = joint.find("parent").get("link")
        p, R = poses[name]
        if body is None:
            frames.append(LinkFrame(name=name, body=None, rotor=None, position=p, rotation=R))
            continue
        G, O = bodies[body]
        frame = {"name": name, "body": body, "rotor": rotor, "position": G.T @ (p - O), "rotation": G.T @ R}
        if rotor is not None:
            _, axis, point = rotors[rotor]
            frame.update({"axis": G.T @ axis, "anchor": G.T @ (point - O)})
        frames.append(LinkFrame(**frame))
    return RobotDescription(urdf=_with_locks(text, root, locked), links=tuple(frames))


def _with_locks(text: str, root: ET.Element, locked: Mapping[str, float]) -> str:
    """The URDF with each locked joint written ``fixed`` at its value (its origin moved by the
    joint's motion); the text itself when nothing is locked."""
    if not locked:
        return text
    for joint in root.findall("joint"):
        name = joint.get("name")
        if name not in locked:
            continue
        xyz, Ro = _origin(joint)
        t, Rm = _motion(joint, locked[name])
        q = matrix_to_quat(Ro @ Rm)
        w, x, y, z = q
        rpy = (math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y)),
               math.asin(max(-1.0, min(1.0, 2 * (w * y - z * x)))),
               math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z)))
        origin = joint.find("origin")
        if origin is None:
            origin = ET.SubElement(joint, "origin")
        origin.set("xyz", " ".join(repr(float(v)) for v in xyz + Ro @ t))
        origin.set("rpy", " ".join(repr(float(v)) for v in rpy))
        joint.set("type", "fixed")
        for tag in ("axis", "limit", "mimic", "dynamics", "safety_controller", "calibration"):
            for child in joint.findall(tag):
                joint.remove(child)
    return '<?xml version="1.0"?>\n' + ET.tostring(root, encoding="unicode")


def link_poses(robot: RobotDescription, bodies: Mapping[str, tuple[np.ndarray, np.ndarray]],
               angles: Mapping[str, float]) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """Every link's world pose (name, position, rotation) from the bodies' poses (name ->
    (O^k, world_R_body)) and the rotors' angles (name -> rad)."""
    out = []
    for link in robot.links:
        if link.body is None:
            out.append((link.name, link.position, link.rotation))
            continue
        O, R = bodies[link.body]
        p, Rl = link.position, link.rotation
        if link.rotor is not None:
            turn = axis_angle_matrix(link.axis, angles[link.rotor])
            p = link.anchor + turn @ (p - link.anchor)
            Rl = turn @ Rl
        out.append((link.name, O + R @ p, R @ Rl))
    return out


def link_transforms(robot: RobotDescription, sim) -> tuple[list[str], np.ndarray, np.ndarray]:
    """The links' world poses from a Simulator's state: names, positions (n, 3), quaternions
    (n, 4; w, x, y, z), from one output call: the bodies' poses and the joint states together."""
    s = sim.snapshot(wrenches=False, invariants=False)
    bodies = {name: (s.body_position[k], quat_to_matrix(s.body_quaternion[k])) for k, name in enumerate(s.body_names)}
    poses = link_poses(robot, bodies, dict(zip(s.joint_names, s.position)))
    names = [name for name, _, _ in poses]
    positions = np.array([p for _, p, _ in poses])
    quaternions = np.array([matrix_to_quat(R) for _, _, R in poses])
    return names, positions, quaternions
