"""Messages -> rerun: the one translator behind `gyro-sim view LOG` and `gyro-sim view --live`.

A :class:`Translator` takes gyro_sim's messages one at a time (:meth:`Translator.message`:
the topic as the node names it without its namespace, the simulated time, the decoded
message: mcap-ros2-support's classes from a log, rclpy's from a live subscription; both
have the ROS field names as attributes), buffers what they draw and sends it to a rerun
RecordingStream in columns on :meth:`Translator.flush` (a log: once at the end; live: a few
times a second).

Entities (timeline ``sim_time``, a duration: simulated seconds):

- ``world/<body>``: the body frame (Transform3D world -> body, with axes); under it ``body``
  (a capsule from O^k to each child's joint point: s^k on a chain; to twice its centre of mass
  on a body without children), ``<rotor>`` (the rotor's disc) with ``<rotor>/spin`` turned by
  kappa_i when the rotor is named (scenes; a URDF does not name them), ``wrench/force`` and
  ``wrench/moment`` (R^k and L^k at O^k in the body's frame);
- ``world/links`` (lines from each body's joint point to each child's and to a tip: on a chain
  the polyline through O^1 ... O^n and the tip), ``world/base`` (the joint points on the base),
  ``world/angular_momentum`` (about O^1, from /diagnostics), ``world/gravity``;
- ``world/legend``: the scene's name and the arrows' scales;
- plots: ``plots/euler/<body>`` (psi, theta, phi; psi and phi unwrapped), ``plots/hinge/<body>``,
  ``plots/slide/<body>`` (a slide's position, m), ``plots/rotor_rate/<rotor>``,
  ``plots/axis_moments/<axis>`` (the commands in force), ``plots/drift/<invariant>`` and
  ``plots/balance/energy_balance`` (log10 of the relative drift of the conserved integrals
  and of E - E0 - W: one readable axis for values from 1e-16 to 1),
  ``plots/imu/<imu>/gyro`` and ``plots/imu/<imu>/accel`` (an IMU's angular velocity and
  specific force in its frame); ``events``.

Arrows are scaled so that the largest value so far is :data:`ARROW_FRACTION` of the chain's
length (a log: the largest of the log).

A new topic type is one handler: ``Translator.HANDLERS[topic] = "_method"`` (exact topic)
or ``Translator.PREFIX_HANDLERS[prefix]`` (one topic per joint or sensor); the method gets
``(t, msg)`` or ``(t, msg, suffix)``.
"""
from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field

import numpy as np

from gyro_sim.msgs import messages as M
from gyro_sim.scene.urdf import quat_z_to
from gyro_sim.viz.chain import Chain, ChainError, from_urdf
from gyro_sim.viz.robot import is_robot_urdf, log_link_poses, log_robot

TIMELINE = "sim_time"
#: the largest arrow of a kind is this fraction of the chain's length
ARROW_FRACTION = 0.5
#: axes drawn at each body frame, as a fraction of the chain's length
AXES_FRACTION = 0.08
#: line and arrow radii, the base point, the gravity arrow (its length and its offset from
#: O^1 sideways), as fractions of the chain's length
LINK_RADIUS_FRACTION = 0.004
ARROW_RADIUS_FRACTION = 0.005
BASE_RADIUS_FRACTION = 0.02
GRAVITY_LENGTH_FRACTION = 0.3
GRAVITY_OFFSET_FRACTION = 0.4
#: drifts at or below this (relative) are drawn at its log10: the floor of double precision
DRIFT_FLOOR = 1e-16
#: at most this many bodies get an Euler-angle plot of their own (the first and the last), and at most this many series
#: share a plot of hinges, rotors or axes (the first ones and the last): more lines are not readable
EULER_PLOT_BODIES = 2
#: at most this many IMUs get their plots (angular velocity, specific force)
IMU_PLOTS = 2
MAX_SERIES = 6

#: colours of the series of a plot, in turn (Okabe-Ito, distinguishable in colour-blind vision)
PALETTE = [(0, 114, 178), (230, 159, 0), (0, 158, 115), (204, 121, 167), (86, 180, 233), (213, 94, 0),
           (240, 228, 66), (150, 150, 150)]

COLORS = {
    "links": (200, 200, 200),
    "body": (70, 130, 180),
    "rotor": (230, 160, 40),
    "marker": (40, 40, 40),
    # arrows: hues apart from the body axes (x red, y green, z blue) and from each other
    "force": (255, 140, 0),
    "moment": (200, 0, 200),
    "momentum": (0, 170, 170),
    "gravity": (120, 120, 120),
    "base": (30, 30, 30),
}

#: the plots in the order the view shows them, with their titles
TITLES = {
    "plots/hinge": "hinge angles (rad)",
    "plots/slide": "slide positions (m)",
    "plots/rotor_rate": "rotor rates (rad/s)",
    "plots/axis_moments": "commands (N m; N on slides)",
    "plots/drift": "log10 |relative drift|",
}
#: entity trees drawn in a plot besides its own
PLOT_EXTRA = {"plots/drift": ["plots/balance"]}
EULER = ("psi", "theta", "phi")


def _xyz(v) -> list[float]:
    return [float(v.x), float(v.y), float(v.z)]


def _pick(items: list, limit: int) -> list:
    """The first limit-1 items and the last: who is shown when there are too many."""
    return items if len(items) <= limit else items[: limit - 1] + items[-1:]


@dataclass
class _Columns:
    """Rows buffered for one entity until the next flush."""

    kind: str
    times: list = field(default_factory=list)
    rows: dict = field(default_factory=dict)

    def add(self, t: float, **values) -> None:
        self.times.append(t)
        for k, v in values.items():
            self.rows.setdefault(k, []).append(v)


class Translator:
    """gyro_sim messages -> rerun entities (module docstring).

    Parameters
    ----------
    rec
        The rerun RecordingStream.
    chain
        The chain's shapes (a log's scene); None: taken from ``robot_description`` when it
        comes (live), the frames drawn from /tf meanwhile.
    axis_names
        The actuated axes (a log's parameters); empty: read from /diagnostics.
    source
        A line for the legend (the log's file name, the node's namespace).
    """

    HANDLERS = {M.JOINT_STATES: "_joint_states", M.TF: "_tf", M.POSES: "_poses", M.DIAGNOSTICS: "_diagnostics",
                M.EVENTS: "_event", M.ROBOT_DESCRIPTION: "_robot_description"}
    PREFIX_HANDLERS = {M.WRENCH_PREFIX: "_wrench", M.IMU_PREFIX: "_imu"}

    def __init__(self, rec, chain: Chain | None = None, *, axis_names=(), source: str = "", frame_prefix: str = ""):
        import rerun as rr

        self.rr, self.rec = rr, rec
        self.chain: Chain | None = None
        self.source = source
        self.frame_prefix = frame_prefix
        self.axis_names = list(axis_names)
        self.entities: set[str] = set()
        self.plots: list[str] = []  # views with data (plots/euler/<body> and TITLES)
        self.series: dict[str, list[str]] = {}  # plot -> names of its series, in order
        self.ranges: dict[str, list[float]] = {}  # plot -> [min, max] of its values
        self.t_range: list[float] | None = None
        self.bbox: list[np.ndarray] | None = None  # [min, max] of the body origins
        self.last_t = 0.0
        self.joint_names: list[str] = []
        self.pose_names: list[str] | None = None
        self.from_tf = False
        self.last_pose: tuple[np.ndarray, np.ndarray] | None = None  # positions, quaternions (n, 3|4)
        self.commanded = False
        self.arrow_max = {"force": 0.0, "moment": 0.0, "momentum": 0.0}
        self.arrow_scale = dict.fromkeys(self.arrow_max, 0.0)
        self._unwrap: dict[str, np.ndarray] = {}
        self._buf: dict[str, _Columns] = {}
        self._warned: set[str] = set()
        self._imus: list[str] = []  # the IMUs plotted, in the order they came
        self._lines: dict[str, tuple] = {}  # plot entity -> (plot, names, colours) of its series
        self.notes: list[str] = []  # one line per problem met (bad description, ...)
        self.robot_links: set[str] = set()  # a URDF robot's links (its own description: viz.robot)
        self.package_path: list[str] = []  # where the robot's package:// meshes are looked for first
        self._static("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP)
        if chain is not None:
            self.set_chain(chain)

    # --- input ----------------------------------------------------------------------------------
    def message(self, topic: str, t: float, msg) -> None:
        """One message of `topic` (without the node's namespace) at simulated time `t` (s)."""
        handler = self.HANDLERS.get(topic)
        if handler is not None:
            getattr(self, handler)(t, msg)
            return
        for prefix, name in self.PREFIX_HANDLERS.items():
            if topic.startswith(prefix):
                getattr(self, name)(t, msg, topic[len(prefix):])
                return

    def _time(self, t: float) -> None:
        self.last_t = t
        if self.t_range is None:
            self.t_range = [t, t]
        else:
            self.t_range = [min(self.t_range[0], t), max(self.t_range[1], t)]

    def _rows(self, entity: str, kind: str) -> _Columns:
        c = self._buf.get(entity)
        if c is None:
            c = self._buf[entity] = _Columns(kind)
        return c

    def _static(self, entity: str, *archetypes) -> None:
        for a in archetypes:
            self.rec.log(entity, a, static=True)
        self.entities.add(entity)

    # --- the chain's shapes ------------------------------------------------------------------------
    def set_chain(self, chain: Chain) -> None:
        """Draw the chain's shapes (static); a chain drawn before is replaced."""
        rr = self.rr
        old = self.chain
        if old is not None:
            if old.key() == chain.key():
                return
            for b in old.bodies:  # shapes of the old chain, not its frames (they are data)
                self.rec.log(f"world/{b.name}/body", rr.Clear(recursive=True), static=True)
                for r in b.rotors:
                    self.rec.log(f"world/{b.name}/{r.name or ''}", rr.Clear(recursive=True), static=True)
        self.chain = chain
        length = chain.length
        self._legend()
        for b in chain.bodies:
            ent = f"world/{b.name}"
            self.rec.log(ent, rr.TransformAxes3D(AXES_FRACTION * length), static=True)
            if b.segments:  # a capsule from O^k to each child's joint point (or to its tip)
                self._static(f"{ent}/body", rr.Capsules3D(lengths=[float(np.linalg.norm(e)) for e in b.segments],
                                                           radii=[b.radius] * len(b.segments),
                                                           quaternions=[quat_z_to(e) for e in b.segments],
                                                           colors=[COLORS["body"]] * len(b.segments)))
            else:
                self._static(f"{ent}/body", rr.Ellipsoids3D(half_sizes=[[b.radius] * 3], colors=[COLORS["body"]]))
            for i, r in enumerate(b.rotors):
                rent = f"{ent}/{r.name or f'rotor{i + 1}'}"
                self._static(rent, rr.Transform3D(translation=r.position, quaternion=quat_z_to(r.axis)))
                self._static(f"{rent}/spin/disc", rr.Cylinders3D(lengths=[r.thickness], radii=[r.radius],
                                                                 colors=[COLORS["rotor"]]))
                z = r.thickness / 2 * 1.05
                self._static(f"{rent}/spin/marker", rr.LineStrips3D([[[0, 0, z], [r.radius, 0, z]]],
                                                                    radii=[0.15 * r.thickness + 1e-4],
                                                                    colors=[COLORS["marker"]]))
        if chain.gravity is not None and np.linalg.norm(chain.gravity) > 0:
            g = chain.gravity
            self._static("world/gravity", rr.Arrows3D(
                vectors=[GRAVITY_LENGTH_FRACTION * length * g / np.linalg.norm(g)],
                origins=[chain.base + [GRAVITY_OFFSET_FRACTION * length, 0, 0]],
                colors=[COLORS["gravity"]], radii=[ARROW_RADIUS_FRACTION * length], labels=["g"]))
        for name, color in (("force", "force"), ("moment", "moment")):
            for b in chain.bodies:
                self.rec.log(f"world/{b.name}/wrench/{name}", rr.Arrows3D.from_fields(
                    colors=[COLORS[color]], radii=[ARROW_RADIUS_FRACTION * length]), static=True)
        self.rec.log("world/links", rr.LineStrips3D.from_fields(radii=[LINK_RADIUS_FRACTION * length],
                                                                colors=[COLORS["links"]]), static=True)
        self.rec.log("world/base", rr.Points3D.from_fields(radii=[BASE_RADIUS_FRACTION * length],
                                                           colors=[COLORS["base"]]), static=True)
        self.rec.log("world/angular_momentum", rr.Arrows3D.from_fields(
            colors=[COLORS["momentum"]], radii=[ARROW_RADIUS_FRACTION * length], labels=["H"]), static=True)

    def _legend(self) -> None:
        name = self.chain.name if self.chain else "waiting for the robot description"
        sF, sL = self.arrow_scale["force"], self.arrow_scale["moment"]
        text = (f"# {name}\n\n{self.source}\n\n"
                "Arrows: orange R^k (joint force), magenta L^k (joint moment), teal total angular momentum "
                "about O^1, grey gravity.")
        if sF or sL:
            text += f"\n\nforce: {1 / sF if sF else 0:.3g} N per m; moment: {1 / sL if sL else 0:.3g} N m per m"
        self._static("world/legend", self.rr.TextDocument(text, media_type="text/markdown"))

    def _robot_description(self, t: float, msg) -> None:
        if is_robot_urdf(msg.data):  # the robot's own URDF: its links drawn where /tf puts them
            try:
                self.robot_links, notes = log_robot(self.rec, msg.data, self.package_path)
            except (ET.ParseError, ValueError, TypeError) as exc:
                self._note(f"robot_description: the robot's links not drawn: {exc}")
                return
            for line in notes:
                self._note(line)
            return
        try:
            chain = from_urdf(msg.data)
        except ChainError as exc:
            self._note(f"robot_description ignored: {exc}")
            return
        if self.chain is not None and [b.name for b in self.chain.bodies] == chain.body_names \
                and self.chain.gravity is not None:
            return  # a log's scene knows more than its URDF (rotor names, gravity)
        self.set_chain(chain)

    def _note(self, line: str) -> None:
        if line not in self._warned:
            self._warned.add(line)
            self.notes.append(line)

    # --- poses ------------------------------------------------------------------------------------
    def _tf(self, t: float, msg) -> None:
        names = [self._body(tr.child_frame_id) for tr in msg.transforms]
        pos = np.array([_xyz(tr.transform.translation) for tr in msg.transforms])
        quat = np.array([_xyz(tr.transform.rotation) + [float(tr.transform.rotation.w)] for tr in msg.transforms])
        bodies = set(self.chain.body_names) if self.chain is not None else set()
        if names and ((self.robot_links and set(names) <= self.robot_links) or (bodies and not bodies & set(names))):
            # a URDF robot's link frames (published beside the bodies'): they move its visuals
            if np.all(np.isfinite(pos)) and np.all(np.isfinite(quat)):
                self._time(t)
                log_link_poses(self._rows, names, pos, quat, t)
            return
        self.from_tf = True
        self._pose(t, names, pos, quat)

    def _body(self, frame: str) -> str:
        """The body of a /tf child frame: the node's frame_prefix taken off (a live view does not
        know it: what comes before the last "/" of a frame that is not a body's name)."""
        frame = frame.removeprefix(self.frame_prefix) if self.frame_prefix else frame
        if "/" in frame and (self.chain is None or frame not in self.chain.body_names):
            frame = frame.rsplit("/", 1)[1]
        return frame

    def _poses(self, t: float, msg) -> None:
        if self.from_tf:
            return  # /tf names the frames: a PoseArray only without it, in the chain's order
        pos = np.array([_xyz(p.position) for p in msg.poses]).reshape(-1, 3)
        quat = np.array([_xyz(p.orientation) + [float(p.orientation.w)] for p in msg.poses]).reshape(-1, 4)
        if self.chain is not None and len(msg.poses) == len(self.chain.bodies):
            self._pose(t, self.chain.body_names, pos, quat)
        elif self.chain is None:  # no names yet: the links through the joint points, no frames
            self._pose(t, [], pos, quat)

    def _pose(self, t: float, names: list[str], pos: np.ndarray, quat: np.ndarray) -> None:
        if not (np.all(np.isfinite(pos)) and np.all(np.isfinite(quat))) or not len(pos):
            return
        self._time(t)
        self.pose_names = names or None
        self.last_pose = (pos, quat)
        lo, hi = pos.min(axis=0), pos.max(axis=0)
        self.bbox = [lo, hi] if self.bbox is None else [np.minimum(self.bbox[0], lo), np.maximum(self.bbox[1], hi)]
        for i, n in enumerate(names):
            self._rows(f"world/{n}", "transform").add(t, translation=pos[i], quaternion=quat[i])
        if self.chain is not None and self.chain.body_names == names:  # the tree's lines, the joint points on the base
            strips = self.chain.strips(pos, quat)
            base = pos[[k for k, p in enumerate(self.chain.parents()) if p < 0]]
        else:  # no names yet: one line through the joint points in order
            strips, base = [pos], pos[:1]
        self._rows("world/links", "strips").add(t, strips=strips)
        self._rows("world/base", "points").add(t, positions=base)

    # --- joint states: angles, rates, commands, rotor spin ----------------------------------------------
    def _joint_states(self, t: float, msg) -> None:
        names = list(msg.name)
        if not self.joint_names:
            self.joint_names = names
        if names != self.joint_names:
            if self.chain is not None and names != self.joint_names:
                self.joint_names = names  # another scene (a reset to a new one, a node restarted)
                self._unwrap.clear()
        pos, vel = np.asarray(msg.position, float), np.asarray(msg.velocity, float)
        eff = np.asarray(msg.effort, float) if len(msg.effort) else np.zeros(len(names))
        if not (len(pos) == len(vel) == len(eff) == len(names)) or not np.all(np.isfinite(np.r_[pos, vel, eff])):
            return
        self._time(t)
        idx = {n: i for i, n in enumerate(names)}
        bodies = (self.chain.body_names if self.chain
                  else sorted({n.rsplit("_", 1)[0] for n in names if n.endswith("_theta")}))
        spherical = [b for b in bodies if all(f"{b}_{a}" in idx for a in EULER)]
        for b in _pick(spherical, EULER_PLOT_BODIES):
            values = pos[[idx[f"{b}_{a}"] for a in EULER]]
            values = self._unwrapped(f"euler/{b}", values, (0, 2))
            self._scalars(f"plots/euler/{b}", f"plots/euler/{b}", [f"{b} {a}" for a in EULER], t, values)
        slides = {b.name for b in self.chain.bodies if b.slide} if self.chain else set()
        hinges = [b for b in bodies if b in idx and b not in spherical and b not in slides]
        for b in _pick(hinges, MAX_SERIES):
            self._scalars(f"plots/hinge/{b}", "plots/hinge", [b], t, [pos[idx[b]]])
        for b in _pick([b for b in bodies if b in idx and b in slides], MAX_SERIES):
            self._scalars(f"plots/slide/{b}", "plots/slide", [b], t, [pos[idx[b]]])
        if self.chain is None:
            return  # hinges and rotors are told apart by the chain's body names
        rotors = [r.name for b in self.chain.bodies for r in b.rotors if r.name in idx]
        for body in self.chain.bodies:
            for r in body.rotors:
                if r.name in idx:
                    k = pos[idx[r.name]]
                    self._rows(f"world/{body.name}/{r.name}/spin", "quaternion").add(
                        t, quaternion=[0.0, 0.0, math.sin(k / 2), math.cos(k / 2)])
        if not rotors:  # a URDF does not name them: the joints that are neither Euler angles nor bodies
            euler_names = {f"{b}_{a}" for b in spherical for a in EULER}
            rotors = [n for n in names if n not in bodies and n not in euler_names]
        for r in _pick(rotors, MAX_SERIES):
            self._scalars(f"plots/rotor_rate/{r}", "plots/rotor_rate", [f"{r} kappa'"], t, [vel[idx[r]]])
        for a in _pick([a for a in self.axis_names if a in idx], MAX_SERIES):
            self._scalars(f"plots/axis_moments/{a}", "plots/axis_moments", [a], t, [eff[idx[a]]])

    def _unwrapped(self, key: str, values: np.ndarray, cols) -> np.ndarray:
        """psi and phi continuous across messages, not folded into (-pi, pi]."""
        values = values.copy()
        prev = self._unwrap.get(key)
        if prev is not None:
            for c in cols:
                values[c] = prev[c] + (values[c] - prev[c] + math.pi) % (2 * math.pi) - math.pi
        self._unwrap[key] = values
        return values

    def _scalars(self, entity: str, plot: str, labels: list[str], t: float, values) -> None:
        values = np.asarray(values, float)
        if entity not in self._lines:
            have = self.series.setdefault(plot, [])
            colors = [PALETTE[(len(have) + j) % len(PALETTE)] for j in range(len(labels))]
            have.extend(labels)
            self._lines[entity] = (plot, labels, colors)  # declared when its data is sent
        r = self.ranges.setdefault(entity, [math.inf, -math.inf])
        r[0], r[1] = min(r[0], float(values.min())), max(r[1], float(values.max()))
        self._rows(entity, "scalars").add(t, scalars=values)

    # --- wrenches ---------------------------------------------------------------------------------------
    def _wrench(self, t: float, msg, joint: str) -> None:
        F, L = _xyz(msg.wrench.force), _xyz(msg.wrench.torque)
        if not np.all(np.isfinite(F + L)):
            return
        if self.chain is not None and joint not in self.chain.body_names:
            return
        self._time(t)
        self._rows(f"world/{joint}/wrench/force", "arrow:force").add(t, vectors=F)
        self._rows(f"world/{joint}/wrench/moment", "arrow:moment").add(t, vectors=L)

    # --- IMUs -------------------------------------------------------------------------------------------
    def _imu(self, t: float, msg, name: str) -> None:
        gyro, accel = _xyz(msg.angular_velocity), _xyz(msg.linear_acceleration)
        if not np.all(np.isfinite(gyro + accel)):
            return
        if name not in self._imus:
            if len(self._imus) >= IMU_PLOTS:
                return
            self._imus.append(name)
        self._time(t)
        self._scalars(f"plots/imu/{name}/gyro", f"plots/imu/{name}/gyro", [f"{name} w{a}" for a in "xyz"], t, gyro)
        self._scalars(f"plots/imu/{name}/accel", f"plots/imu/{name}/accel", [f"{name} f{a}" for a in "xyz"], t, accel)

    # --- diagnostics -----------------------------------------------------------------------------------
    def _diagnostics(self, t: float, msg) -> None:
        d = {k: v for k, v in M.diagnostic_numbers(msg).items() if math.isfinite(v)}
        self._time(t)
        if not self.axis_names:
            self.axis_names = [k[len("axis_moment_"):-len("_Nm")] for k in d
                               if k.startswith("axis_moment_") and k.endswith("_Nm")]
        if d.get(M.WORK_KEY, 0.0) != 0.0:
            self.commanded = True
        keys = [M.vector_key("angular_momentum_O1", a, "Nms") for a in "xyz"]
        if all(k in d for k in keys) and self.last_pose is not None:
            self._rows("world/angular_momentum", "arrow:momentum").add(
                t, vectors=[d[k] for k in keys], origins=self.last_pose[0][0])
        # under commands the energy is not conserved (its change is the work: see the balance)
        for key, value in d.items():
            if key.endswith(M.DRIFT_SUFFIX) and not (self.commanded and key in _NOT_CONSERVED_UNDER_COMMANDS):
                name = key[: -len(M.DRIFT_SUFFIX)]
                self._scalars(f"plots/drift/{name}", "plots/drift", [f"{name} drift"], t, [_log10(value)])
        if M.BALANCE_REL_KEY in d:
            self._scalars("plots/balance/energy_balance", "plots/drift", ["E - E0 - W"], t,
                          [_log10(d[M.BALANCE_REL_KEY])])

    def _event(self, t: float, msg) -> None:
        self.rec.set_time(TIMELINE, duration=max(t, self.last_t))
        self.rec.log("events", self.rr.TextLog(str(msg.data), level="INFO"))
        self.entities.add("events")

    # --- output ------------------------------------------------------------------------------------------
    def flush(self) -> None:
        """Send what was buffered since the last flush, in columns."""
        rr = self.rr
        if self.commanded:  # the energy is not conserved under commands: its drift is not shown
            for name in ("energy", "jacobi"):
                ent = f"plots/drift/{M.drift_key(name)[: -len(M.DRIFT_SUFFIX)]}"
                self._buf.pop(ent, None)
                if ent in self._lines:
                    self._drop_series(ent)
        length = self.chain.length if self.chain else 1.0
        for kind in self.arrow_max:
            vs = [np.asarray(c.rows["vectors"]) for c in self._buf.values() if c.kind == f"arrow:{kind}"]
            big = max((float(np.max(np.linalg.norm(v, axis=-1))) for v in vs if v.size), default=0.0)
            if big > self.arrow_max[kind]:
                self.arrow_max[kind] = big
        scale = {k: ARROW_FRACTION * length / m if m > 0 else 0.0 for k, m in self.arrow_max.items()}
        if scale != self.arrow_scale:
            self.arrow_scale = scale
            self._legend()
        buf, self._buf = self._buf, {}
        for entity, c in buf.items():
            if not c.times:
                continue
            cols = {k: np.asarray(v, float) for k, v in c.rows.items() if k not in ("strips", "positions")}
            if c.kind == "transform":
                columns = rr.Transform3D.columns(translation=cols["translation"], quaternion=cols["quaternion"])
            elif c.kind == "quaternion":
                columns = rr.Transform3D.columns(quaternion=cols["quaternion"])
            elif c.kind == "strips":  # several lines at each time (a tree's branches)
                columns = rr.LineStrips3D.columns(strips=[np.asarray(p, float) for row in c.rows["strips"]
                                                          for p in row]).partition([len(r) for r in c.rows["strips"]])
            elif c.kind == "points":  # several points at each time
                columns = rr.Points3D.columns(positions=np.concatenate(c.rows["positions"])).partition(
                    [len(r) for r in c.rows["positions"]])
            elif c.kind.startswith("arrow:"):
                v = cols["vectors"] * scale[c.kind[len("arrow:"):]]
                columns = (rr.Arrows3D.columns(vectors=v, origins=cols["origins"]) if "origins" in cols
                           else rr.Arrows3D.columns(vectors=v))
            else:
                plot, labels, colors = self._lines[entity]
                if entity not in self.entities:
                    self.rec.log(entity, rr.SeriesLines(names=labels, colors=colors), static=True)
                    if plot not in self.plots:
                        self.plots.append(plot)
                columns = rr.Scalars.columns(scalars=cols["scalars"])
            self.rec.send_columns(entity, indexes=[rr.TimeColumn(TIMELINE, duration=np.asarray(c.times))],
                                  columns=columns)
            self.entities.add(entity)

    def _drop_series(self, entity: str) -> None:
        plot, labels, _ = self._lines.pop(entity)
        self.series[plot] = [x for x in self.series.get(plot, []) if x not in labels]
        if entity in self.entities:  # already drawn (live): cleared
            self.rec.log(entity, self.rr.Clear(recursive=True), static=True)
            self.entities.discard(entity)

    def plot_range(self, plot: str) -> tuple[float, float] | None:
        """(min, max) of the values drawn in `plot` so far, or None."""
        rs = [self.ranges[e] for e, (p, _, _) in self._lines.items() if p == plot and e in self.ranges]
        if not rs:
            return None
        return min(r[0] for r in rs), max(r[1] for r in rs)

    def views(self) -> list[str]:
        """The plots with data, in the view's order."""
        euler = [p for p in self.plots if p.startswith("plots/euler/")]
        imus = [p for p in self.plots if p.startswith("plots/imu/")]
        return euler + [p for p in TITLES if p in self.plots] + imus

    def eye(self):
        """(position, target) of a camera looking at the motion so far, or None."""
        if self.bbox is None:
            return None
        centre = 0.5 * (self.bbox[0] + self.bbox[1])
        span = max(float(np.max(self.bbox[1] - self.bbox[0])), self.chain.length if self.chain else 0.0, 1e-3)
        return centre + EYE_DIRECTION * EYE_DISTANCE * span, centre


#: the 3D camera looks at the centre of the motion from this direction, this many spans away
EYE_DIRECTION = np.array([1.0, -1.2, 0.6]) / np.linalg.norm([1.0, -1.2, 0.6])
EYE_DISTANCE = 1.6


def canonical(topic: str, names) -> str:
    """The translator's name of a node's topic (`names`: its gyro_sim.msgs.messages.TopicNames):
    those of a node at the root, which :attr:`Translator.HANDLERS` know."""
    exact = {names.joint_states: M.JOINT_STATES, names.robot_description: M.ROBOT_DESCRIPTION,
             names.events: M.EVENTS, names.poses: M.POSES}
    if topic in exact:
        return exact[topic]
    for prefix, root in ((names.wrench_prefix, M.WRENCH_PREFIX), (f"{names.node}/imu/", M.IMU_PREFIX)):
        if topic.startswith(prefix):
            return root + topic[len(prefix):]
    return topic


_NOT_CONSERVED_UNDER_COMMANDS = frozenset({M.drift_key("energy"), M.drift_key("jacobi")})


def title(plot: str) -> str | None:
    """The title of a plot of :meth:`Translator.views` (None: not a plot)."""
    if plot.startswith("plots/euler/"):
        return f"Euler angles of {plot[len('plots/euler/'):]} (rad)"
    if plot.startswith("plots/imu/"):
        name, kind = plot[len("plots/imu/"):].rsplit("/", 1)
        return f"IMU {name}: " + ("angular velocity (rad/s)" if kind == "gyro" else "specific force (m/s^2)")
    return TITLES.get(plot)


def _log10(value: float) -> float:
    return math.log10(max(abs(value), DRIFT_FLOOR))

