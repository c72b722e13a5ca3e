"""The chain's shapes for drawing, and as a URDF on /robot_description.

Every log carries the URDF of its scene as one std_msgs/String on /robot_description (log
time 0): links named after the bodies, so that the /tf frames world -> <body> place them.
Viewers that draw a robot from its description and its TF (rerun opening the .mcap
directly, Foxglove, RViz) then show the moving bodies without gyro_sim. Each body is a
cylinder from its joint point to each child's (s^k on a chain; twice its centre of mass on a
body without children) of the scene's visual radius; each rotor a disc at h_i about e_i, sized
from its mass and inertia, its visual named after the rotor. Each body's joint is
``floating`` from its parent's link (``world`` for a body on the base), named
``<parent>_to_<body>``: the description is the scene's tree, the poses come from /tf (world ->
each body), not from joint states. A ``<gyro_sim base="x y z" gravity="x y z" slides="a b"/>`` element (which URDF
readers skip) gives a viewer the base point, gravity and the bodies on slides (whose joint
states are positions in m, not angles), so a live view draws what a log's view draws.
"""
from __future__ import annotations

import math
from xml.sax.saxutils import quoteattr

import numpy as np

from gyro_sim.dynamics.rotations import quat_to_matrix

#: radius of a body without a visual radius, as a fraction of the chain's length
DEFAULT_RADIUS_FRACTION = 0.03
#: rotor disc thickness when the inertia does not give one, as a fraction of its radius
ROTOR_THICKNESS_FRACTION = 0.25
#: rotor discs are at most this much of the chain's length in radius
ROTOR_MAX_RADIUS_FRACTION = 0.25
#: a rotor without mass or inertia is drawn this big (fraction of the chain's length)
ROTOR_DEFAULT_RADIUS_FRACTION = 0.05
#: thinnest rotor disc, as a fraction of its radius
ROTOR_MIN_THICKNESS_FRACTION = 0.1
BODY_RGBA = (0.27, 0.51, 0.71, 1.0)
ROTOR_RGBA = (0.90, 0.63, 0.16, 1.0)
ROOT_LINK = "world"


def parents(scene) -> list[int]:
    """Each body's parent (its index; -1: the base): its `parent`, else the body before it."""
    return [k - 1 if b.parent is None else int(b.parent) for k, b in enumerate(scene.bodies)]


def body_segments(scene) -> list[list[np.ndarray]]:
    """Per body, the segments it is drawn along, from O^k in its frame: to each child's joint
    point (its `joint.at`, else s^k), or twice its centre of mass when it has none (a body
    without children, or whose children hang at O^k); none when that is zero too. A chain's
    body: [s^k], its last [2 c]."""
    bodies = scene.bodies
    out: list[list[np.ndarray]] = [[] for _ in bodies]
    for k, p in enumerate(parents(scene)):
        if p < 0:
            continue
        at = bodies[k].joint.at if bodies[k].joint.at is not None else bodies[p].next_joint
        at = np.asarray(at, dtype=float)
        if np.linalg.norm(at) > 0 and not any(np.array_equal(at, s) for s in out[p]):
            out[p].append(at)
    for k, b in enumerate(bodies):
        if not out[k] and np.linalg.norm(b.com) > 0:
            out[k].append(2.0 * np.asarray(b.com, dtype=float))
    return out


def chain_length(scene) -> float:
    """Sum of the bodies' drawn lengths (m): the scale of everything drawn."""
    return max(sum(float(np.linalg.norm(s)) for segments in body_segments(scene) for s in segments), 1e-3)


def body_radius(body, length: float) -> float:
    return body.visual_radius or DEFAULT_RADIUS_FRACTION * length


def rotor_size(rotor, length: float) -> tuple[float, float]:
    """(radius, thickness) of a rotor drawn as a uniform disc of its mass and inertia:
    A = m R^2 / 2, B = m (3 R^2 + h^2) / 12."""
    if rotor.mass > 0 and rotor.axial_inertia > 0:
        r = math.sqrt(2.0 * rotor.axial_inertia / rotor.mass)
        h2 = 12.0 * rotor.transverse_inertia / rotor.mass - 3.0 * r * r
        h = math.sqrt(h2) if h2 > 0 else ROTOR_THICKNESS_FRACTION * r
    else:
        r, h = ROTOR_DEFAULT_RADIUS_FRACTION * length, 0.0
    r = min(r, ROTOR_MAX_RADIUS_FRACTION * length)
    return r, min(max(h, ROTOR_MIN_THICKNESS_FRACTION * r), r)


def quat_z_to(v) -> list[float]:
    """Quaternion (x, y, z, w) of the shortest rotation turning +z onto the direction of v."""
    v = np.asarray(v, dtype=float)
    n = np.linalg.norm(v)
    if n == 0:
        return [0.0, 0.0, 0.0, 1.0]
    c = float(v[2] / n)
    if c < -1 + 1e-12:
        return [1.0, 0.0, 0.0, 0.0]  # half turn about x
    axis = np.cross([0.0, 0.0, 1.0], v / n)
    q = np.array([axis[0], axis[1], axis[2], 1.0 + c])
    return (q / np.linalg.norm(q)).tolist()


def rpy_z_to(v) -> tuple[float, float, float]:
    """URDF roll, pitch, yaw (fixed axes x, y, z) of the rotation turning +z onto v."""
    x, y, z, w = quat_z_to(v)
    # R = Rz(yaw) Ry(pitch) Rx(roll), read from the matrix entries of the quaternion
    R = quat_to_matrix(np.array([w, x, y, z]))
    r00, r10, r20, r21, r22 = R[0, 0], R[1, 0], R[2, 0], R[2, 1], R[2, 2]
    return math.atan2(r21, r22), math.atan2(-r20, math.hypot(r00, r10)), math.atan2(r10, r00)


def _v(a) -> str:
    return " ".join(repr(float(x)) for x in a)


def _visual(xyz, rpy, radius: float, length: float, material: str, rgba, name: str | None = None) -> str:
    named = f" name={quoteattr(name)}" if name else ""
    return (f'    <visual{named}><origin xyz="{_v(xyz)}" rpy="{_v(rpy)}"/>'
            f'<geometry><cylinder radius="{radius!r}" length="{length!r}"/></geometry>'
            f'<material name="{material}"><color rgba="{_v(rgba)}"/></material></visual>')


def urdf(scene) -> str:
    """The URDF text of a scene (module docstring)."""
    length = chain_length(scene)
    lines = ['<?xml version="1.0"?>', '<robot name="gyro_sim">', f'  <link name="{ROOT_LINK}"/>']
    # what a viewer draws besides the links (URDF readers skip an element they do not know)
    gravity = f' gravity="{_v(scene.gravity)}"' if scene.gravity is not None else ""
    slides = " ".join(b.name for b in scene.bodies if b.joint.type == "slide")
    slides = f" slides={quoteattr(slides)}" if slides else ""
    lines.append(f'  <gyro_sim base="{_v(scene.base.position)}"{gravity}{slides}/>')
    for b, segments, p in zip(scene.bodies, body_segments(scene), parents(scene)):
        lines.append(f"  <link name={quoteattr(b.name)}>")
        for ext in segments:
            lines.append(_visual(ext / 2, rpy_z_to(ext), body_radius(b, length), float(np.linalg.norm(ext)), "body",
                                 BODY_RGBA))
        for r in b.rotors:
            rad, thick = rotor_size(r, length)
            lines.append(_visual(r.position, rpy_z_to(r.axis), rad, thick, "rotor", ROTOR_RGBA, r.name))
        lines.append("  </link>")
        parent = scene.bodies[p].name if p >= 0 else ROOT_LINK
        lines.append(f"  <joint name={quoteattr(parent + '_to_' + b.name)} type=\"floating\">"
                     f"<parent link={quoteattr(parent)}/><child link={quoteattr(b.name)}/></joint>")
    lines.append("</robot>")
    return "\n".join(lines) + "\n"
