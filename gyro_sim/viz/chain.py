"""The bodies' shapes as the views draw them, from a scene (logs) or from a URDF (live).

A log embeds its scene: every body, rotor and the gravity are known by name. A running node
publishes only the URDF of its scene on ``robot_description`` (gyro_sim.scene.urdf): links
named after the bodies with cylinder visuals (material ``body`` from the joint point to each
child's, material ``rotor`` for each rotor's disc), each joined to its parent's link. Both
become a :class:`Chain` (a chain, or a tree: each body knows its parent), which is all the
translator needs.
"""
from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field

import numpy as np

from gyro_sim.errors import GyroSimError
from gyro_sim.scene.urdf import ROOT_LINK, body_radius, body_segments, chain_length, parents, rotor_size


class ChainError(GyroSimError, ValueError):
    """A robot description that does not describe a chain."""


@dataclass
class RotorShape:
    """A rotor's disc: centre and axis in its body's frame (m), radius and thickness (m)."""

    name: str | None
    position: np.ndarray
    axis: np.ndarray
    radius: float
    thickness: float


@dataclass
class BodyShape:
    """A body: the segments it is drawn along from O^k in its frame (a capsule of `radius` along
    each: to each child's joint point, or twice its centre of mass), its rotors, its parent's
    name (None: the base); `slide`: its joint is a slide (its joint state a position in m)."""

    name: str
    segments: list[np.ndarray]
    radius: float
    rotors: list[RotorShape] = field(default_factory=list)
    slide: bool = False
    parent: str | None = None

    @property
    def extent(self) -> np.ndarray:
        """Where its tip is drawn from O^k (a body without children): its first segment."""
        return self.segments[0] if self.segments else np.zeros(3)


@dataclass
class Chain:
    """What the 3D view draws of a scene."""

    name: str
    bodies: list[BodyShape]
    length: float
    gravity: np.ndarray | None = None
    base: np.ndarray = field(default_factory=lambda: np.zeros(3))

    @property
    def body_names(self) -> list[str]:
        return [b.name for b in self.bodies]

    def parents(self) -> list[int]:
        """Each body's parent (its index; -1: the base)."""
        index = {b.name: k for k, b in enumerate(self.bodies)}
        return [index.get(b.parent, -1) if b.parent is not None else -1 for b in self.bodies]

    def strips(self, pos: np.ndarray, quat: np.ndarray) -> list[np.ndarray]:
        """The lines through the joint points at the bodies' positions `pos` (n, 3) and
        quaternions `quat` (n, 4; x, y, z, w): from each body's O^k to each child's O^j, and from
        a body without children to its tip. A chain is one polyline O^1 ... O^n, tip; a branch
        starts at its parent's joint point."""
        ps = self.parents()
        strips: list[list[np.ndarray]] = []
        strip_of: dict[int, int] = {}
        has_child = set(ps)
        for k, p in enumerate(ps):
            if p >= 0 and k == p + 1:  # the first child continues its parent's line
                strip_of[k] = strip_of[p]
                strips[strip_of[k]].append(pos[k])
            else:
                strip_of[k] = len(strips)
                strips.append([pos[p], pos[k]] if p >= 0 else [pos[k]])
            if k not in has_child:
                strips[strip_of[k]].append(pos[k] + rotate(quat[k], self.bodies[k].extent))
        return [np.array(s) for s in strips]

    def key(self) -> tuple:
        """What is drawn of the chain, comparable (two descriptions of one scene: equal)."""
        def v(a) -> tuple:
            return tuple(float(x) for x in np.ravel(a))

        return (self.name, self.length, None if self.gravity is None else v(self.gravity), v(self.base),
                tuple((b.name, tuple(v(s) for s in b.segments), b.radius,
                       tuple((r.name, v(r.position), v(r.axis), r.radius, r.thickness) for r in b.rotors),
                       b.slide, b.parent)
                      for b in self.bodies))


def from_scene(scene) -> Chain:
    """The chain of a loaded scene (gyro_sim.scene)."""
    length = chain_length(scene)
    bodies = []
    for b, segments, p in zip(scene.bodies, body_segments(scene), parents(scene)):
        rotors = []
        for r in b.rotors:
            rad, thick = rotor_size(r, length)
            rotors.append(RotorShape(r.name, np.asarray(r.position, float), np.asarray(r.axis, float), rad, thick))
        bodies.append(BodyShape(b.name, segments, body_radius(b, length), rotors, b.joint.type == "slide",
                                scene.bodies[p].name if p >= 0 else None))
    g = None if scene.gravity is None else np.asarray(scene.gravity, float)
    return Chain(scene.name, bodies, length, g, np.asarray(scene.base.position, float))


def _rpy_z(rpy) -> np.ndarray:
    """The z axis of the rotation Rz(yaw) Ry(pitch) Rx(roll) (URDF's fixed-axis rpy)."""
    r, p, y = rpy
    return np.array([math.cos(y) * math.sin(p) * math.cos(r) + math.sin(y) * math.sin(r),
                     math.sin(y) * math.sin(p) * math.cos(r) - math.cos(y) * math.sin(r),
                     math.cos(p) * math.cos(r)])


def _floats(text: str | None, n: int) -> np.ndarray:
    values = [float(v) for v in (text or " ".join(["0"] * n)).split()]
    if len(values) != n or not all(math.isfinite(v) for v in values):
        raise ChainError(f"expected {n} finite numbers, got {text!r}")
    return np.array(values)


def from_urdf(text: str) -> Chain:
    """The chain of a gyro_sim URDF (gyro_sim.scene.urdf.urdf); ChainError if it is not one.

    Its rotors are named by their visuals' names (their spin is drawn), its base, gravity and
    the bodies on slides given by its ``<gyro_sim>`` element.
    """
    try:
        root = ET.fromstring(text)
    except ET.ParseError as exc:
        raise ChainError(f"robot_description is not XML: {exc}") from None
    if root.tag != "robot":
        raise ChainError(f"robot_description is not a URDF (root element <{root.tag}>)")
    bodies = []
    parent_of = {}
    for joint in root.findall("joint"):
        child, parent = joint.find("child"), joint.find("parent")
        if child is not None and parent is not None and parent.get("link") != ROOT_LINK:
            parent_of[child.get("link")] = parent.get("link")
    try:
        for link in root.findall("link"):
            name = link.get("name", "")
            if name == ROOT_LINK or not name:
                continue
            segments, radius, rotors = [], 0.0, []
            for vis in link.findall("visual"):
                cyl = vis.find("geometry/cylinder")
                if cyl is None:
                    continue
                origin = vis.find("origin")
                xyz = _floats(origin.get("xyz") if origin is not None else None, 3)
                axis = _rpy_z(_floats(origin.get("rpy") if origin is not None else None, 3))
                r, ln = float(cyl.get("radius", "0")), float(cyl.get("length", "0"))
                mat = vis.find("material")
                if mat is not None and mat.get("name") == "rotor":
                    rotors.append(RotorShape(vis.get("name") or None, xyz, axis, r, ln))
                else:
                    segments.append(axis * ln)
                    radius = r
            bodies.append(BodyShape(name, segments, radius, rotors, parent=parent_of.get(name)))
    except (TypeError, ValueError) as exc:
        raise ChainError(f"robot_description: {exc}") from None
    if not bodies:
        raise ChainError("robot_description has no links besides the root")
    length = sum(float(np.linalg.norm(s)) for b in bodies for s in b.segments) or 1.0
    extra = root.find("gyro_sim")  # the base and gravity (gyro_sim.scene.urdf)
    gravity, base = None, np.zeros(3)
    if extra is not None:
        try:
            if extra.get("gravity"):
                gravity = _floats(extra.get("gravity"), 3)
            base = _floats(extra.get("base"), 3)
        except (TypeError, ValueError) as exc:
            raise ChainError(f"robot_description: <gyro_sim>: {exc}") from None
        slides = set((extra.get("slides") or "").split())
        for b in bodies:
            b.slide = b.name in slides
    return Chain(root.get("name", "robot"), bodies, length, gravity, base)



def rotate(q_xyzw: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate vectors v (..., 3) by quaternions (..., 4) x, y, z, w."""
    u, w = q_xyzw[..., :3], q_xyzw[..., 3:4]
    t = 2.0 * np.cross(u, v)
    return v + w * t + np.cross(u, t)
