"""The Gazebo IMUs of a URDF model: ``<gazebo reference="LINK"><sensor type="imu">``.

MuJoCo reads a URDF's links and joints and ignores its ``<gazebo>`` extensions; this module
reads the IMU sensors there (SDF's ``<sensor>``: sdformat's sensor.sdf, imu.sdf and noise.sdf),
both the ``<imu><angular_velocity>/<linear_acceleration><x|y|z><noise>`` form of SDF 1.5 and
later (Gazebo classic and gz-sim alike) and the ``<imu><noise><rate>/<accel>`` form of SDF 1.4.
:mod:`gyro_sim.scene.mjcf` puts a site at each one's pose on its link, so that MuJoCo's
compiler carries it with the link wherever it fuses fixed links, and makes it an IMU of the
scene (docs/models.md, "Sensors").

Gazebo's Gaussian noise model (gz-sensors' GaussianNoiseModel, Gazebo classic's alike) adds
to each sample ``bias + N(mean, stddev)``: ``stddev`` is a standard deviation per sample; the
bias is drawn once at start (``bias_mean``, ``bias_stddev``, with a random sign) and, in
gz-sim, moves as a first-order Gauss-Markov process driven by ``dynamic_bias_stddev`` with
correlation time ``dynamic_bias_correlation_time`` tau (step ``phi b + N(0, s_d)``,
``s_d^2 = sigma_b^2 tau / 2 (1 - exp(-2 dt / tau))``, that is ``sigma_b^2 dt`` for dt << tau:
a random walk of density sigma_b). This module reports the numbers as the file gives them;
the importer converts them to densities.
"""
from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field

import numpy as np

__all__ = ["GazeboImu", "GazeboSensors", "read_gazebo_sensors", "rpy_quaternion"]

#: the Gaussian noise types of SDF's noise.sdf (the second rounds the output as well)
GAUSSIAN_TYPES = ("gaussian", "gaussian_quantized")
#: the axes of SDF's <angular_velocity> and <linear_acceleration>
AXES = ("x", "y", "z")
#: numbers of a <pose>: x y z roll pitch yaw, or x y z qx qy qz qw (rotation_format quat_xyzw)
POSE_RPY, POSE_QUAT = 6, 7


@dataclass
class NoiseSpec:
    """One sensor's noise (gyro or accelerometer), the largest of its axes."""

    stddev: float = 0.0  # white noise, standard deviation per sample
    walk: float = 0.0  # dynamic_bias_stddev: the bias walk's density (with a correlation time)
    correlation_time: float | None = None  # s, of the dynamic bias (None: none given)


@dataclass
class GazeboImu:
    """One ``<sensor type="imu">`` of a ``<gazebo reference="LINK">``."""

    name: str  # the sensor's name attribute
    link: str  # the link it is on
    position: np.ndarray  # (3,) from the link's origin, link frame (<pose>)
    quaternion: np.ndarray  # (4,) w, x, y, z: link from sensor (<pose>)
    rate: float | None  # <update_rate> (Hz); None: none given or 0 (every physics step)
    gyro: NoiseSpec = field(default_factory=NoiseSpec)
    accel: NoiseSpec = field(default_factory=NoiseSpec)
    notes: list[str] = field(default_factory=list)  # what of it is left out, one line each

    @property
    def element(self) -> str:
        """How messages name it."""
        return f"gazebo sensor {self.name!r} on link {self.link!r}"


@dataclass
class GazeboSensors:
    """What a URDF's ``<gazebo>`` extensions hold of sensors."""

    imus: list[GazeboImu] = field(default_factory=list)
    skipped: list[str] = field(default_factory=list)  # sensors not imported: "'cam' (camera) on link 'head'"
    notes: list[str] = field(default_factory=list)  # other sensors' lines, whole
    errors: list[tuple[str, str]] = field(default_factory=list)  # (element, why)


def rpy_quaternion(rpy) -> np.ndarray:
    """The quaternion (w, x, y, z) of URDF's and SDF's roll, pitch, yaw: fixed axes x, y, z,
    R = Rz(yaw) Ry(pitch) Rx(roll)."""
    r, p, y = (0.5 * float(a) for a in rpy)
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    return np.array([cy * cp * cr + sy * sp * sr,
                     cy * cp * sr - sy * sp * cr,
                     cy * sp * cr + sy * cp * sr,
                     sy * cp * cr - cy * sp * sr])


class _Reader:
    """One file's sensors; problems collected, never raised."""

    def __init__(self) -> None:
        self.out = GazeboSensors()

    def fail(self, element: str, why: str) -> None:
        self.out.errors.append((element, why))

    def number(self, node: ET.Element | None, element: str, label: str, minimum: float | None = None,
               default: float = 0.0) -> float | None:
        """The number in `node`'s text (`default` without the node); None after a failure, said
        as ``<element>: <label> ...``."""
        if node is None:
            return default
        text = (node.text or "").strip()
        try:
            value = float(text)
        except ValueError:
            self.fail(element, f"{label} {text!r} is not a number")
            return None
        if not math.isfinite(value):
            self.fail(element, f"{label} must be finite (got {text})")
            return None
        if minimum is not None and value < minimum:
            self.fail(element, f"{label} must be >= {minimum:g} (got {text})")
            return None
        return value

    def pose(self, sensor: ET.Element, imu: GazeboImu) -> bool:
        """Set `imu`'s position and quaternion from the sensor's <pose>; False when it cannot be
        (a failure, or a frame this reader does not resolve: a note)."""
        pose = sensor.find("pose")
        if pose is None:
            return True
        relative = (pose.get("relative_to") or pose.get("frame") or "").strip()
        if relative and relative != imu.link:
            self.out.notes.append(f"{imu.element}: not imported: its <pose> is relative to "
                                  f"{relative!r}; only a pose on its own link is read")
            return False
        parts = (pose.text or "").split()
        quat = (pose.get("rotation_format") or "euler_rpy").strip() == "quat_xyzw"
        size = POSE_QUAT if quat else POSE_RPY
        try:
            values = [float(p) for p in parts]
        except ValueError:
            values = []
        if len(values) != size or not all(math.isfinite(v) for v in values):
            self.fail(imu.element, f"<pose> {(pose.text or '').strip()!r} must be {size} finite numbers")
            return False
        imu.position = np.array(values[:3])
        if quat:
            x, y, z, w = values[3:]
            q = np.array([w, x, y, z])
            norm = float(np.linalg.norm(q))
            if norm == 0.0:
                self.fail(imu.element, "<pose> has a zero quaternion")
                return False
            imu.quaternion = q / norm
        else:
            rpy = np.array(values[3:])
            if (pose.get("degrees") or "").strip().lower() in ("true", "1"):
                rpy = np.radians(rpy)
            imu.quaternion = rpy_quaternion(rpy)
        return True

    def noise(self, node: ET.Element | None, imu: GazeboImu, what: str, kind: str | None = None) -> dict | None:
        """One <noise> element's numbers (None: a failure); {} for none or type "none". `kind`:
        the type when the element does not say it (SDF 1.4's <rate> and <accel>)."""
        if node is None:
            return {}
        kind = (kind or node.get("type") or node.findtext("type") or "none").strip().lower()
        if kind == "none":
            return {}
        if kind not in GAUSSIAN_TYPES:
            imu.notes.append(f"{what} noise of type {kind!r} not modelled (Gaussian noise only)")
            return {}
        element = imu.element
        out = {}
        for key, minimum in (("mean", None), ("stddev", 0.0), ("bias_mean", None), ("bias_stddev", 0.0),
                             ("dynamic_bias_stddev", 0.0), ("dynamic_bias_correlation_time", None),
                             ("precision", 0.0)):
            value = self.number(node.find(key), element, f"{what} <{key}>", minimum)
            if value is None:
                return None
            out[key] = value
        return out

    def combine(self, axes: list[dict], imu: GazeboImu, what: str) -> NoiseSpec:
        """The noise of one sensor from its axes' (x, y, z) noise: the largest of each number,
        and a note for what gyro_sim leaves out."""
        spec = NoiseSpec()
        if not any(axes):
            return spec
        stddev, walk, tau = ([a.get(key, 0.0) for a in axes]
                             for key in ("stddev", "dynamic_bias_stddev", "dynamic_bias_correlation_time"))
        spec.stddev = max(stddev)
        if len(set(stddev)) > 1:
            imu.notes.append(f"{what} stddev differs by axis ({', '.join(f'{v:g}' for v in stddev)}): "
                             "the largest taken for all three")
        driven = [w if t > 0.0 else 0.0 for w, t in zip(walk, tau)]  # Gazebo drives it only with tau > 0
        if any(driven):
            spec.walk = max(driven)
            spec.correlation_time = min(t for w, t in zip(driven, tau) if w > 0.0)
            if len(set(driven)) > 1:
                imu.notes.append(f"{what} dynamic_bias_stddev differs by axis: the largest taken")
        left = [key for key in ("mean", "bias_mean", "bias_stddev", "precision")
                if any(a.get(key, 0.0) != 0.0 for a in axes)]
        if left:
            imu.notes.append(f"{what} {', '.join(left)} not modelled (gyro_sim's bias starts at 0 "
                             "and walks; no offset, no quantization)")
        return spec

    def imu(self, sensor: ET.Element, name: str, link: str) -> None:
        imu = GazeboImu(name=name, link=link, position=np.zeros(3), quaternion=np.array([1.0, 0.0, 0.0, 0.0]),
                        rate=None)
        ok = self.pose(sensor, imu)
        rate = self.number(sensor.find("update_rate"), imu.element, "<update_rate>", minimum=0.0)
        if rate is None:
            ok = False
        elif rate > 0.0:
            imu.rate = rate
        body = sensor.find("imu")
        gyro_axes: list[dict] = []
        accel_axes: list[dict] = []
        if body is not None:
            for group, axes, what in (("angular_velocity", gyro_axes, "gyro"),
                                      ("linear_acceleration", accel_axes, "accelerometer")):
                node = body.find(group)
                if node is None:
                    continue
                for axis in AXES:  # an axis without <noise> has none
                    element = node.find(axis)
                    values = self.noise(element.find("noise") if element is not None else None, imu, what)
                    if values is None:
                        ok = False
                    else:
                        axes.append(values)
            old = body.find("noise")  # SDF 1.4: <noise><type/><rate/><accel/></noise>
            if old is not None:
                kind = (old.get("type") or (old.findtext("type") or "gaussian")).strip().lower()
                for part, axes, what in (("rate", gyro_axes, "gyro"), ("accel", accel_axes, "accelerometer")):
                    node = old.find(part)
                    if node is None:
                        continue
                    values = self.noise(node, imu, what, kind)
                    if values is None:
                        ok = False
                    else:
                        axes.extend([values] * len(AXES))
            if body.find("orientation_reference_frame") is not None:
                imu.notes.append("orientation_reference_frame not kept (the orientation is the IMU "
                                 "frame's in the world)")
        imu.gyro = self.combine(gyro_axes, imu, "gyro")
        imu.accel = self.combine(accel_axes, imu, "accelerometer")
        if ok:
            self.out.imus.append(imu)

    def read(self, root: ET.Element) -> GazeboSensors:
        links = {link.get("name") for link in root.findall("link")}
        for sensor in root.findall("sensor"):  # URDF's own <sensor> (cameras and rays)
            name = sensor.get("name") or "(unnamed)"
            self.out.skipped.append(f"{name!r} (URDF <sensor>)")
        for gazebo in root.findall("gazebo"):
            link = gazebo.get("reference")
            for sensor in gazebo.findall("sensor"):
                name = (sensor.get("name") or "").strip()
                kind = (sensor.get("type") or "").strip()
                where = f"on link {link!r}" if link else "without a reference link"
                if kind != "imu":
                    self.out.skipped.append(f"{name or '(unnamed)'!r} ({kind or 'no type'}) {where}")
                    continue
                if not name:
                    self.fail(f"gazebo sensor of type 'imu' {where}", "has no name (SDF requires one)")
                    continue
                if not link:
                    self.out.notes.append(f"gazebo sensor {name!r}: not imported: no reference link "
                                          "(an IMU is fixed to a link)")
                    continue
                if link not in links:
                    self.out.notes.append(f"gazebo sensor {name!r}: not imported: no link named "
                                          f"{link!r}")
                    continue
                self.imu(sensor, name, link)
        return self.out


def read_gazebo_sensors(path: str) -> GazeboSensors:
    """The sensors of a URDF file's ``<gazebo>`` extensions (module docstring). A file that
    cannot be parsed gives an error, as does an IMU with a number that cannot be read."""
    try:
        root = ET.parse(path).getroot()
    except (ET.ParseError, OSError) as exc:
        out = GazeboSensors()
        out.errors.append(("gazebo", f"cannot read the <gazebo> elements: {exc}"))
        return out
    return _Reader().read(root)
