"""`gyro-sim view`: a gyro_sim log as a rerun recording with a blueprint.

The 3D view (entity ``world``) draws the chain from the log's /tf (or /gyro_sim/poses) and
the embedded scene:

- ``world/links``: the polyline through the joint points O^1 ... O^n and the tip;
- ``world/<body>``: the body frame (Transform3D world -> body, with axes); under it
  ``body`` (a capsule along s^k of the scene's visual radius), ``<rotor>`` (the rotor's disc
  at h_i about e_i, its size from its inertia) with ``<rotor>/spin`` turned by the rotor angle
  kappa_i (a radial marker makes the spin visible), and ``wrench/force`` and
  ``wrench/moment`` (R^k and L^k at O^k, in the body's frame);
- ``world/angular_momentum``: the total angular momentum about O^1 (from /diagnostics);
- ``world/gravity``: the gravity direction at the base; ``world/base``: O^1.

Arrow lengths are scaled so that the largest value of the log is about half the chain's
length; the scales are in ``world/legend`` (N per m, N m per m).

Plots (timeline ``sim_time``): ``plots/euler/<body>`` (psi, theta, phi), ``plots/hinge/<body>``,
``plots/rotor_rate/<rotor>`` (kappa_i'), ``plots/axis_moments/<axis>`` (the commands in
force, from the joint-state efforts), ``plots/drift/<invariant>`` (relative drift of the
conserved integrals from /diagnostics; the energy's only without commands),
``plots/balance/energy_balance`` (E - E0 - W, conserved with or without commands), and
``events`` (resets and other markers).

rerun-sdk is imported here only: the rest of gyro_sim does not need it.
"""
from __future__ import annotations

import math
import os
import socket
import subprocess
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from gyro_sim.errors import GyroSimError
from gyro_sim.msgs import messages as M
from gyro_sim.log.mcap_log import LogError, read_info
from gyro_sim.scene.urdf import body_extent, body_radius, chain_length, quat_z_to, rotor_size

APP_ID = "gyro_sim"
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
#: the 3D camera looks at the centre of the motion from this direction, this many spans away
EYE_DIRECTION = np.array([1.0, -1.2, 0.6]) / np.linalg.norm([1.0, -1.2, 0.6])
EYE_DISTANCE = 1.6

#: room left after the last time of a plot (fraction of the log's span): keeps the last tick
#: label (e.g. "+30s") inside the plot instead of cut at its right edge
TIME_PAD_FRACTION = 0.04

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


# =========================================================================================
# The log as arrays
# =========================================================================================
@dataclass
class Series:
    """Time series read from a log (times in s)."""

    joint_t: np.ndarray = field(default_factory=lambda: np.zeros(0))
    joint_names: list = field(default_factory=list)
    position: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    velocity: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    effort: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    pose_t: np.ndarray = field(default_factory=lambda: np.zeros(0))
    pose_names: list = field(default_factory=list)
    pose_pos: np.ndarray = field(default_factory=lambda: np.zeros((0, 0, 3)))  # (T, n, 3)
    pose_quat: np.ndarray = field(default_factory=lambda: np.zeros((0, 0, 4)))  # (T, n, 4) xyzw
    wrench: dict = field(default_factory=dict)  # joint -> (t (T,), force (T,3), torque (T,3))
    diag_t: np.ndarray = field(default_factory=lambda: np.zeros(0))
    diag: dict = field(default_factory=dict)  # key -> (T,)
    events: list = field(default_factory=list)  # (t, text)


def _xyz(v) -> list[float]:
    return [v.x, v.y, v.z]


def load_series(path: str | os.PathLike) -> Series:
    """Decode the topics the view needs (log time order)."""
    from gyro_sim.log.mcap_log import iter_messages, log_topic_names

    topics = log_topic_names(path)  # a namespaced node's log too
    s = Series()
    js_t, pos, vel, eff = [], [], [], []
    tf_t, tf_p, tf_q, tf_names = [], [], [], None
    pa_t, pa_p, pa_q = [], [], []
    wr: dict = {}
    dg_t, dg = [], []
    for topic, _, t_ns, msg in iter_messages(path):
        t = t_ns / 1e9
        if topic == topics.joint_states:
            if not s.joint_names:
                s.joint_names = list(msg.name)
            if list(msg.name) != s.joint_names:
                continue  # a different joint set (another scene): not plotted
            js_t.append(t)
            pos.append(list(msg.position))
            vel.append(list(msg.velocity))
            eff.append(list(msg.effort) or [0.0] * len(s.joint_names))
        elif topic == M.TF:
            names = [tr.child_frame_id.removeprefix(topics.frame_prefix) for tr in msg.transforms]
            if tf_names is None:
                tf_names = names
            if names != tf_names:
                continue
            tf_t.append(t)
            tf_p.append([_xyz(tr.transform.translation) for tr in msg.transforms])
            tf_q.append([_xyz(tr.transform.rotation) + [tr.transform.rotation.w] for tr in msg.transforms])
        elif topic == topics.poses:
            pa_t.append(t)
            pa_p.append([_xyz(p.position) for p in msg.poses])
            pa_q.append([_xyz(p.orientation) + [p.orientation.w] for p in msg.poses])
        elif topic.startswith(topics.wrench_prefix):
            j = topic[len(topics.wrench_prefix):]
            wr.setdefault(j, ([], [], []))
            wr[j][0].append(t)
            wr[j][1].append(_xyz(msg.wrench.force))
            wr[j][2].append(_xyz(msg.wrench.torque))
        elif topic == M.DIAGNOSTICS:
            dg_t.append(t)
            dg.append(M.diagnostic_numbers(msg))
        elif topic == topics.events:
            s.events.append((t, msg.data))
    s.joint_t = np.array(js_t)
    n = len(s.joint_names)
    s.position, s.velocity, s.effort = (np.array(a, dtype=float).reshape(-1, n) for a in (pos, vel, eff))
    if tf_t:
        s.pose_t, s.pose_names = np.array(tf_t), tf_names
        s.pose_pos, s.pose_quat = np.array(tf_p), np.array(tf_q)
    elif pa_t:
        s.pose_t = np.array(pa_t)
        s.pose_pos, s.pose_quat = np.array(pa_p), np.array(pa_q)
    s.wrench = {j: (np.array(a), np.array(b), np.array(c)) for j, (a, b, c) in wr.items()}
    s.diag_t = np.array(dg_t)
    keys = sorted({k for d in dg for k in d})
    s.diag = {k: np.array([d.get(k, math.nan) for d in dg]) for k in keys}
    return s


def _rotate(q_xyzw: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate vectors v (..., 3) by quaternions (..., 4) x, y, z, w."""
    u, w = q_xyzw[..., :3], q_xyzw[..., 3:4]
    t = 2.0 * np.cross(u, v)
    return v + w * t + np.cross(u, t)


# =========================================================================================
# The recording
# =========================================================================================
def _scale(vectors: list[np.ndarray], length: float) -> float:
    big = max((float(np.max(np.linalg.norm(v, axis=-1))) for v in vectors if v.size), default=0.0)
    return ARROW_FRACTION * length / big if big > 0 else 0.0


def build_recording(path: str | os.PathLike, rec) -> dict:
    """Log the whole view of the log at `path` into the rerun RecordingStream `rec`.

    Returns what was drawn: {"entities": [...], "views": [...]} (the blueprint's views).
    """
    import rerun as rr

    info = read_info(path)
    scene = info.scene()
    s = load_series(path)
    length = chain_length(scene)
    bodies = [b.name for b in scene.bodies]
    entities: list[str] = []

    def send(entity, times, columns):
        rec.send_columns(entity, indexes=[rr.TimeColumn(TIMELINE, duration=times)], columns=columns)
        entities.append(entity)

    def static(entity, *archetypes):
        for a in archetypes:
            rec.log(entity, a, static=True)
        entities.append(entity)

    static("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP)
    static("world/legend", rr.TextDocument(
        f"# {scene.name}\n\nlog: `{Path(path).name}`\n\n"
        "Arrows: orange R^k (joint force), magenta L^k (joint moment), teal total angular momentum "
        "about O^1, grey gravity.", media_type="text/markdown"))

    # --- bodies: frames, shapes, rotors -------------------------------------------------------------
    if s.pose_t.size:
        names = s.pose_names or bodies
        idx = {n: i for i, n in enumerate(names)}
        for b in scene.bodies:
            if b.name not in idx:
                continue
            i = idx[b.name]
            ent = f"world/{b.name}"
            send(ent, s.pose_t, rr.Transform3D.columns(translation=s.pose_pos[:, i], quaternion=s.pose_quat[:, i]))
            rec.log(ent, rr.TransformAxes3D(AXES_FRACTION * length), static=True)
            ext = body_extent(b)
            radius = body_radius(b, length)
            if np.linalg.norm(ext) > 0:
                static(f"{ent}/body", rr.Capsules3D(lengths=[float(np.linalg.norm(ext))], radii=[radius],
                                                    quaternions=[quat_z_to(ext)], colors=[COLORS["body"]]))
            else:
                static(f"{ent}/body", rr.Ellipsoids3D(half_sizes=[[radius] * 3], colors=[COLORS["body"]]))
            for r in b.rotors:
                rent = f"{ent}/{r.name}"
                rad, thick = rotor_size(r, length)
                static(rent, rr.Transform3D(translation=np.asarray(r.position, float), quaternion=quat_z_to(r.axis)))
                static(f"{rent}/spin/disc", rr.Cylinders3D(lengths=[thick], radii=[rad], colors=[COLORS["rotor"]]))
                static(f"{rent}/spin/marker", rr.LineStrips3D([[[0, 0, thick / 2 * 1.05], [rad, 0, thick / 2 * 1.05]]],
                                                              radii=[0.15 * thick + 1e-4], colors=[COLORS["marker"]]))
                if r.name in s.joint_names and s.joint_t.size:
                    k = s.position[:, s.joint_names.index(r.name)]
                    q = np.stack([np.zeros_like(k), np.zeros_like(k), np.sin(k / 2), np.cos(k / 2)], axis=1)
                    send(f"{rent}/spin", s.joint_t, rr.Transform3D.columns(quaternion=q))
        # links through the joint points and the tip
        tip_body = scene.bodies[-1]
        i_last = idx.get(tip_body.name)
        if i_last is not None and all(b in idx for b in bodies):
            pts = [s.pose_pos[:, idx[b]] for b in bodies]
            tip = s.pose_pos[:, i_last] + _rotate(s.pose_quat[:, i_last], np.broadcast_to(body_extent(tip_body), (len(s.pose_t), 3)))
            strips = np.stack(pts + [tip], axis=1)  # (T, n+1, 3)
            send("world/links", s.pose_t, rr.LineStrips3D.columns(strips=list(strips)))
            rec.log("world/links", rr.LineStrips3D.from_fields(radii=[LINK_RADIUS_FRACTION * length], colors=[COLORS["links"]]), static=True)
            first = s.pose_pos[:, idx[bodies[0]]]
            send("world/base", s.pose_t, rr.Points3D.columns(positions=first))
            rec.log("world/base", rr.Points3D.from_fields(radii=[BASE_RADIUS_FRACTION * length], colors=[COLORS["base"]]), static=True)
            # total angular momentum about O^1
            keys = [M.vector_key("angular_momentum_O1", a, "Nms") for a in "xyz"]
            if s.diag_t.size and all(k in s.diag for k in keys):
                H = np.stack([s.diag[k] for k in keys], axis=1)
                sH = _scale([H], length)
                O1 = np.stack([np.interp(s.diag_t, s.pose_t, first[:, a]) for a in range(3)], axis=1)
                send("world/angular_momentum", s.diag_t, rr.Arrows3D.columns(vectors=H * sH, origins=O1))
                rec.log("world/angular_momentum", rr.Arrows3D.from_fields(
                    colors=[COLORS["momentum"]], radii=[ARROW_RADIUS_FRACTION * length], labels=["H"]), static=True)
    # gravity
    if scene.gravity is not None and np.linalg.norm(scene.gravity) > 0:
        g = np.asarray(scene.gravity, float)
        static("world/gravity", rr.Arrows3D(vectors=[GRAVITY_LENGTH_FRACTION * length * g / np.linalg.norm(g)],
                                            origins=[np.asarray(scene.base.position, float) + [GRAVITY_OFFSET_FRACTION * length, 0, 0]],
                                            colors=[COLORS["gravity"]], radii=[ARROW_RADIUS_FRACTION * length], labels=["g"]))
    # joint wrenches, in the body frames
    if s.wrench:
        sF = _scale([f for _, f, _ in s.wrench.values()], length)
        sL = _scale([L for _, _, L in s.wrench.values()], length)
        for j, (t, F, L) in s.wrench.items():
            if j not in bodies:
                continue
            send(f"world/{j}/wrench/force", t, rr.Arrows3D.columns(vectors=F * sF))
            rec.log(f"world/{j}/wrench/force", rr.Arrows3D.from_fields(colors=[COLORS["force"]], radii=[ARROW_RADIUS_FRACTION * length]), static=True)
            send(f"world/{j}/wrench/moment", t, rr.Arrows3D.columns(vectors=L * sL))
            rec.log(f"world/{j}/wrench/moment", rr.Arrows3D.from_fields(colors=[COLORS["moment"]], radii=[ARROW_RADIUS_FRACTION * length]), static=True)
        rec.log("world/legend/scales", rr.TextDocument(
            f"force: {1 / sF if sF else 0:.3g} N per m; moment: {1 / sL if sL else 0:.3g} N m per m"), static=True)

    # --- plots ------------------------------------------------------------------------------------------
    counters: dict[str, int] = {}

    def lines(entity: str, labels: list[str]):
        """Names and colours of the series of `entity`, colours in turn within its plot."""
        plot = "/".join(entity.split("/")[:2])
        i = counters.get(plot, 0)
        counters[plot] = i + len(labels)
        colors = [PALETTE[(i + j) % len(PALETTE)] for j in range(len(labels))]
        rec.log(entity, rr.SeriesLines(names=labels, colors=colors), static=True)

    views = ["world"]
    names = s.joint_names
    plotted = set()
    if s.joint_t.size:
        for b in scene.bodies:
            cols = [names.index(f"{b.name}_{a}") for a in ("psi", "theta", "phi") if f"{b.name}_{a}" in names]
            if len(cols) == 3:
                euler = s.position[:, cols].copy()
                euler[:, 0] = np.unwrap(euler[:, 0])  # psi and phi continuous, not folded into (-pi, pi]
                euler[:, 2] = np.unwrap(euler[:, 2])
                send(f"plots/euler/{b.name}", s.joint_t, rr.Scalars.columns(scalars=euler))
                lines(f"plots/euler/{b.name}", [f"{b.name} psi", f"{b.name} theta", f"{b.name} phi"])
                plotted.add("plots/euler")
            elif b.name in names:
                send(f"plots/hinge/{b.name}", s.joint_t, rr.Scalars.columns(scalars=s.position[:, names.index(b.name)]))
                lines(f"plots/hinge/{b.name}", [b.name])
                plotted.add("plots/hinge")
            for r in b.rotors:
                if r.name in names:
                    send(f"plots/rotor_rate/{r.name}", s.joint_t, rr.Scalars.columns(scalars=s.velocity[:, names.index(r.name)]))
                    lines(f"plots/rotor_rate/{r.name}", [f"{r.name} kappa'"])
                    plotted.add("plots/rotor_rate")
        for axis in info.params.get("axis_names", []):
            if axis in names:
                send(f"plots/axis_moments/{axis}", s.joint_t, rr.Scalars.columns(scalars=s.effort[:, names.index(axis)]))
                lines(f"plots/axis_moments/{axis}", [axis])
                plotted.add("plots/axis_moments")
    # under commands the energy is not conserved (its change is the work: see the balance),
    # so its drift would only dwarf the integrals that are
    commanded = M.WORK_KEY in s.diag and bool(np.any(s.diag[M.WORK_KEY] != 0))
    not_conserved = {M.drift_key("energy"), M.drift_key("jacobi")} if commanded else set()
    for key, values in s.diag.items():
        if key.endswith(M.DRIFT_SUFFIX) and key not in not_conserved and np.all(np.isfinite(values)):
            name = key[: -len(M.DRIFT_SUFFIX)]
            send(f"plots/drift/{name}", s.diag_t, rr.Scalars.columns(scalars=values))
            lines(f"plots/drift/{name}", [f"{name} drift"])
            plotted.add("plots/drift")
    if M.BALANCE_REL_KEY in s.diag and np.all(np.isfinite(s.diag[M.BALANCE_REL_KEY])):
        # E - E(0) - W: conserved with or without commands (gyro_sim.snapshot)
        send("plots/balance/energy_balance", s.diag_t, rr.Scalars.columns(scalars=s.diag[M.BALANCE_REL_KEY]))
        lines("plots/balance/energy_balance", ["E - E0 - W"])
        plotted.add("plots/balance")
    for t, text in s.events:
        rec.set_time(TIMELINE, duration=t)
        rec.log("events", rr.TextLog(text, level="INFO"))
    if s.events:
        entities.append("events")
    views += [v for v in ("plots/euler", "plots/hinge", "plots/rotor_rate", "plots/axis_moments", "plots/drift",
                                "plots/balance") if v in plotted]
    eye = None
    if s.pose_t.size:
        pts = s.pose_pos.reshape(-1, 3)
        centre = 0.5 * (pts.min(axis=0) + pts.max(axis=0))
        span = max(float(np.max(pts.max(axis=0) - pts.min(axis=0))), length)
        eye = (centre + EYE_DIRECTION * EYE_DISTANCE * span, centre)
    times = [a for a in (s.joint_t, s.pose_t, s.diag_t) if a.size]
    t_range = (min(float(a[0]) for a in times), max(float(a[-1]) for a in times)) if times else None
    return {"entities": entities, "views": views, "scene": scene.name, "eye": eye, "t_range": t_range}


TITLES = {
    "plots/euler": "Euler angles psi, theta, phi (rad, psi and phi unwrapped)",
    "plots/hinge": "hinge angles (rad)",
    "plots/rotor_rate": "rotor rates kappa' (rad/s)",
    "plots/axis_moments": "axis moments (N m)",
    "plots/drift": "drift of the conserved integrals (relative)",
    "plots/balance": "energy balance E - E0 - W (relative)",
}


def blueprint(views: list[str], scene_name: str = "", *, eye=None, play_state: str | None = None,
              t_range: tuple[float, float] | None = None):
    """The layout: the 3D chain on the left, the plots stacked on the right.

    `eye`: (position, look_target) of the 3D camera, world frame (None: rerun's default).
    `t_range`: (first, last) time of the log (s): the plots' time axis, with room after the
    last time for its tick label.
    """
    import rerun as rr
    import rerun.blueprint as rrb

    axis_x = None
    if t_range is not None and t_range[1] > t_range[0]:
        pad = TIME_PAD_FRACTION * (t_range[1] - t_range[0])
        axis_x = rrb.TimeAxis(view_range=rr.encodings.TimeRange(
            start=rrb.TimeRangeBoundary.absolute(seconds=t_range[0]),
            end=rrb.TimeRangeBoundary.absolute(seconds=t_range[1] + pad)))
    plots = [rrb.TimeSeriesView(origin=v, name=TITLES[v], axis_x=axis_x) for v in views if v in TITLES]
    eye_controls = None
    if eye is not None:
        eye_controls = rrb.EyeControls3D(position=eye[0], look_target=eye[1], eye_up=[0, 0, 1])
    chain = rrb.Spatial3DView(origin="world", name=f"chain: {scene_name}" if scene_name else "chain",
                              eye_controls=eye_controls)
    main = rrb.Horizontal(chain, rrb.Vertical(*plots), column_shares=[3, 2]) if plots else chain
    return rrb.Blueprint(main, rrb.TimePanel(state="collapsed", timeline=TIMELINE, play_state=play_state),
                         rrb.SelectionPanel(state="collapsed"), rrb.BlueprintPanel(state="collapsed"))


def view(path: str | os.PathLike, save: str | os.PathLike | None = None, *, spawn: bool = True,
         play_state: str | None = None) -> dict:
    """Build the recording of a log; save it to `save` (.rrd) or spawn the viewer.

    `play_state`: "paused" | "playing" | "following" (None: rerun's default).
    """
    import rerun as rr

    if not Path(path).is_file():
        raise LogError(f"{path}: no such file")
    rec = rr.RecordingStream(APP_ID, recording_id=f"gyro_sim:{Path(path).resolve()}")
    # the blueprint needs the views, which need the data: the stream buffers until a sink is set
    drawn = build_recording(path, rec)
    bp = blueprint(drawn["views"], drawn["scene"], eye=drawn.get("eye"), play_state=play_state,
                   t_range=drawn.get("t_range"))
    if save is not None:
        rec.save(str(save), default_blueprint=bp)  # writes what is buffered, then streams the rest
        rec.flush()
        rec.disconnect()  # closes the file (footer written): complete when view() returns
    elif spawn:
        rec.spawn(default_blueprint=bp)
        rec.flush()
    return drawn


# =========================================================================================
# Headless screenshot
# =========================================================================================
#: how long the headless viewer may take to start, load a recording and settle (s)
SCREENSHOT_TIMEOUT = 120.0
#: the viewer's start-up notification ("Listening for gRPC connections") stays on the picture
#: for about a second of painting (measured < 1.1 s, rerun 0.41): pictures are compared only
#: after this long
SETTLE_SECONDS = 2.0


class ScreenshotError(GyroSimError, RuntimeError):
    """The headless viewer did not start, load or paint."""


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def screenshot(exe: str, rrd: str | os.PathLike, png: str | os.PathLike, size: str = "1200x800", *,
               timeout: float = SCREENSHOT_TIMEOUT) -> dict:
    """A PNG of the viewer showing the recording `rrd`, once all of it is drawn.

    ``rerun x.rrd --screenshot-to`` takes its picture a fixed 10 frames after start, whatever
    has been loaded by then: with a software renderer (lavapipe) a long recording is often only
    partly ingested, and the plots come out empty. Here a headless viewer (``exe``, the rerun
    binary) is driven through its control API instead: the recording is opened, the viewer is
    waited on until it reports nothing left to load, the time cursor is put at the end of the
    log (paused, so nothing moves), and pictures are taken until two in a row are identical
    (the data is all drawn), the first of them at least SETTLE_SECONDS after the first picture
    (the start-up notification gone). The top panel (menu, renderer warnings) is hidden.
    Returns {"seconds", "frames"}.
    """
    from rerun.experimental import ViewerClient

    t0 = time.monotonic()
    deadline = t0 + timeout
    port = _free_port()
    env = dict(os.environ)
    env.setdefault("RUST_LOG", "error")  # keeps log notifications off the picture
    env.setdefault("XDG_RUNTIME_DIR", tempfile.gettempdir())
    with tempfile.TemporaryFile() as err:
        proc = subprocess.Popen([exe, "--headless", "--window-size", size, "--port", str(port),
                                 "--bind", "127.0.0.1", "--hide-welcome-screen"],
                                env=env, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=err)

        def fail(what: str):
            err.seek(0)
            tail = err.read()[-2000:].decode(errors="replace")
            raise ScreenshotError(f"{what} (a headless viewer needs Vulkan: apt-get install "
                                  f"mesa-vulkan-drivers libvulkan1)\n{tail}")

        def wait(cond, what: str, step: float = 0.05):
            while True:
                if proc.poll() is not None:
                    fail(f"the viewer exited (code {proc.returncode}) {what}")
                try:
                    value = cond()
                except (ConnectionError, OSError, RuntimeError, TimeoutError):
                    value = None
                if value:
                    return value
                if time.monotonic() > deadline:
                    fail(f"timed out after {timeout:.0f} s {what}")
                time.sleep(step)

        try:
            def connected():
                socket.create_connection(("127.0.0.1", port), timeout=1.0).close()
                return ViewerClient.connect(f"rerun+http://127.0.0.1:{port}/proxy")

            client = wait(connected, "while starting")
            wait(client.get_state, "while starting")
            client.open(str(Path(rrd).resolve()))
            client.run_command("ui.toggle_top_panel")

            def loaded():
                st = client.get_state()
                if st.loading or st.active_recording is None:
                    return None
                for rec in st.recordings:
                    if rec.store_id == st.active_recording:
                        for tl in rec.timelines:
                            if tl.name == TIMELINE and tl.end is not None:
                                return (tl.end,)
                return None

            (end,) = wait(loaded, f"while loading {rrd}")
            client.set_time(TIMELINE, duration=np.timedelta64(int(end), "ns"), play_state="paused")
            frames, previous, first = 0, None, None
            while True:
                image = client.take_screenshot()
                frames += 1
                now = time.monotonic()
                first = now if first is None else first
                if image and image == previous and previous_at - first >= SETTLE_SECONDS:
                    break
                previous, previous_at = image, now
                if proc.poll() is not None or time.monotonic() > deadline:
                    fail(f"the picture did not settle in {timeout:.0f} s")
            Path(png).write_bytes(image)
        finally:
            proc.terminate()
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
    return {"seconds": time.monotonic() - t0, "frames": frames}
