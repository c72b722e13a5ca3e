"""The chain's shapes as the views draw them, from a scene (logs) or from a URDF (live).

A log embeds its scene: every body, rotor and the gravity are known by name. A running node
publishes only the URDF of its scene on ``robot_description`` (gyro_sim.scene.urdf): links
named after the bodies with cylinder visuals (material ``body`` along s^k, material ``rotor``
for each rotor's disc). Both become a :class:`Chain`, which is all the translator needs.
"""
from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field

import numpy as np

from gyro_sim.errors import GyroSimError
from gyro_sim.scene.urdf import ROOT_LINK, body_extent, body_radius, chain_length, rotor_size


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
    """A body: its vector s^k (the capsule along it, of `radius`) and its rotors; `slide`: its
    joint is a slide (its joint state a position in m)."""

    name: str
    extent: np.ndarray
    radius: float
    rotors: list[RotorShape] = field(default_factory=list)
    slide: bool = False


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

    def key(self) -> tuple:
        """What is drawn of the chain, comparable (two descriptions of one scene: equal)."""
        def v(a) -> tuple:
            return tuple(float(x) for x in np.ravel(a))

        return (self.name, self.length, None if self.gravity is None else v(self.gravity), v(self.base),
                tuple((b.name, v(b.extent), b.radius,
                       tuple((r.name, v(r.position), v(r.axis), r.radius, r.thickness) for r in b.rotors),
                       b.slide)
                      for b in self.bodies))


def from_scene(scene) -> Chain:
    """The chain of a loaded scene (gyro_sim.scene)."""
    length = chain_length(scene)
    bodies = []
    for b in scene.bodies:
        rotors = []
        for r in b.rotors:
            rad, thick = rotor_size(r, length)
            rotors.append(RotorShape(r.name, np.asarray(r.position, float), np.asarray(r.axis, float), rad, thick))
        bodies.append(BodyShape(b.name, np.asarray(body_extent(b), float), body_radius(b, length), rotors,
                                b.joint.type == "slide"))
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
    try:
        for link in root.findall("link"):
            name = link.get("name", "")
            if name == ROOT_LINK or not name:
                continue
            extent, radius, rotors = np.zeros(3), 0.0, []
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
                    extent, radius = axis * ln, r
            bodies.append(BodyShape(name, extent, radius, rotors))
    except (TypeError, ValueError) as exc:
        raise ChainError(f"robot_description: {exc}") from None
    if not bodies:
        raise ChainError("robot_description has no links besides the root")
    length = sum(float(np.linalg.norm(b.extent)) for b in bodies) or 1.0
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
