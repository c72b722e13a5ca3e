"""`gyro-sim view LOG`: a gyro_sim log as a rerun recording with a blueprint.

The log's messages go through the translator that `gyro-sim view --live` uses
(gyro_sim.viz.translate: its docstring lists the entities and plots); the chain's shapes come
from the scene the log embeds. This module adds the layout (:func:`blueprint`: the 3D chain on
the left, the plots in a grid on the right, each with a y range that fits its data and leaves
room for its legend) and the headless screenshot.

rerun-sdk is imported here only when a view is built: the rest of gyro_sim does not need it.
"""
from __future__ import annotations

import math
import os
import socket
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np

from gyro_sim.errors import GyroSimError
from gyro_sim.log.mcap_log import LogError, LogReader
from gyro_sim.viz.chain import from_scene
from gyro_sim.viz.translate import PLOT_EXTRA, TIMELINE, Translator, canonical, title

APP_ID = "gyro_sim"

#: room left after the last time of a plot (fraction of the log's span): keeps the last tick
#: label (e.g. "+30s") inside the plot instead of cut at its right edge
TIME_PAD_FRACTION = 0.04
#: room above and below the data of a plot (fraction of its span); a constant series gets a
#: span of MIN_SPAN_FRACTION of its value (MIN_SPAN if it is 0) instead of none
Y_PAD_FRACTION = 0.03
MIN_SPAN_FRACTION = 0.2
MIN_SPAN = 1.0
#: at most this many steps of the y axis's tick spacing between its ends
MAX_STEPS = 6
#: the legend (top left) takes about this fraction of a plot's height per series: the y range
#: is extended upwards by as much, so that the legend sits above the data
LEGEND_ROW_FRACTION = 0.12
#: the plots are laid out in this many columns; the 3D view and the plots share the width so
PLOT_COLUMNS = 2
COLUMN_SHARES = [1, 1]


def build_recording(path: str | os.PathLike, rec) -> dict:
    """Log the whole view of the log at `path` into the rerun RecordingStream `rec`.

    Returns what was drawn: {"entities", "views", "scene", "eye", "t_range", "ranges",
    "series"} (the views of the blueprint, the y range and the series of each plot).
    """
    with LogReader(path) as log:
        info = log.info
        names = log.topic_names()  # a namespaced node's log too
        tr = Translator(rec, from_scene(info.scene()), axis_names=info.params.get("axis_names", []),
                        source=f"log: `{Path(path).name}`", frame_prefix=names.frame_prefix)
        for topic, _, t_ns, msg in log.messages():
            tr.message(canonical(topic, names), t_ns / 1e9, msg)
    tr.flush()
    return drawn(tr)


def drawn(tr: Translator) -> dict:
    """What a translator has drawn so far, as :func:`blueprint` takes it."""
    views = ["world"] + tr.views()
    return {"entities": sorted(tr.entities), "views": views, "scene": tr.chain.name if tr.chain else "",
            "eye": tr.eye(), "t_range": tuple(tr.t_range) if tr.t_range else None,
            "ranges": {v: tr.plot_range(v) for v in views[1:]},
            "series": {v: list(tr.series.get(v, [])) for v in views[1:]}}


def y_range(lo: float, hi: float, series: int) -> tuple[float, float]:
    """A y range showing [lo, hi] with room above for a legend of `series` rows, its ends on
    multiples of a power of ten at most MAX_STEPS of them apart: the viewer labels its ticks
    at powers of ten only when they are far enough apart, so this keeps 2 to MAX_STEPS + 1
    labelled ticks on any plot (a constant series included)."""
    span = hi - lo
    if not span > 0:
        span = MIN_SPAN_FRACTION * abs(hi) or MIN_SPAN
        lo, hi = lo - span / 2, hi + span / 2
    free = 1.0 - min(LEGEND_ROW_FRACTION * series, 0.6)  # the part of the height below the legend
    step = 10.0 ** math.floor(math.log10(span))
    while True:
        bottom, top = math.floor(lo / step) * step, math.ceil(hi / step) * step
        while hi - bottom > free * (top - bottom):
            top += step
        if (top - bottom) / step <= MAX_STEPS + 1e-9:
            break
        step *= 10.0
    pad = Y_PAD_FRACTION * (top - bottom)
    return bottom - pad, top + pad


def blueprint(views: list[str], scene_name: str = "", *, eye=None, play_state: str | None = None,
              t_range: tuple[float, float] | None = None, ranges: dict | None = None,
              series: dict | None = None, window: float | None = None):
    """The layout: the 3D chain on the left, the plots in a grid on the right.

    `eye`: (position, look_target) of the 3D camera, world frame (None: rerun's default).
    `t_range`: (first, last) time of the log (s): the plots' time axis, with room after the
    last time for its tick label; `window` (s) instead: the plots show the last `window`
    seconds before the time cursor (live), or the first `window` seconds from the first time
    while the data spans less. `ranges`: plot -> (min, max) of its values, and
    `series`: plot -> names of its series: the y axis then fits the data and its legend.
    """
    import rerun as rr
    import rerun.blueprint as rrb

    axis_x = None
    if window is not None and t_range is not None and t_range[1] - t_range[0] < window:
        axis_x = rrb.TimeAxis(view_range=rr.encodings.TimeRange(  # filling from the left
            start=rrb.TimeRangeBoundary.absolute(seconds=t_range[0]),
            end=rrb.TimeRangeBoundary.absolute(seconds=t_range[0] + (1 + TIME_PAD_FRACTION) * window)))
    elif window is not None:
        axis_x = rrb.TimeAxis(view_range=rr.encodings.TimeRange(
            start=rrb.TimeRangeBoundary.cursor_relative(seconds=-window),
            end=rrb.TimeRangeBoundary.cursor_relative(seconds=TIME_PAD_FRACTION * window)))
    elif t_range is not None and t_range[1] > t_range[0]:
        pad = TIME_PAD_FRACTION * (t_range[1] - t_range[0])
        axis_x = rrb.TimeAxis(view_range=rr.encodings.TimeRange(
            start=rrb.TimeRangeBoundary.absolute(seconds=t_range[0]),
            end=rrb.TimeRangeBoundary.absolute(seconds=t_range[1] + pad)))
    plots = []
    for v in views:
        if title(v) is None:
            continue
        axis_y = None
        r = (ranges or {}).get(v)
        if r is not None and all(math.isfinite(x) for x in r):
            axis_y = rrb.ScalarAxis(range=y_range(r[0], r[1], len((series or {}).get(v, [])) or 1))
        contents = [f"+ /{v}/**"] + [f"+ /{x}/**" for x in PLOT_EXTRA.get(v, [])]
        plots.append(rrb.TimeSeriesView(origin="/", contents=contents, name=title(v), axis_x=axis_x, axis_y=axis_y,
                                        plot_legend=rrb.PlotLegend(corner="LeftTop", visible=True)))
    eye_controls = None
    if eye is not None:
        eye_controls = rrb.EyeControls3D(position=eye[0], look_target=eye[1], eye_up=[0, 0, 1])
    chain = rrb.Spatial3DView(origin="world", name=f"chain: {scene_name}" if scene_name else "chain",
                              eye_controls=eye_controls)
    if plots:
        main = rrb.Horizontal(chain, rrb.Grid(*plots, grid_columns=PLOT_COLUMNS if len(plots) > 2 else 1),
                              column_shares=COLUMN_SHARES)
    else:
        main = chain
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
    got = build_recording(path, rec)
    bp = blueprint(got["views"], got["scene"], eye=got["eye"], play_state=play_state, t_range=got["t_range"],
                   ranges=got["ranges"], series=got["series"])
    if save is not None:
        rec.save(str(save), default_blueprint=bp)  # writes what is buffered, then streams the rest
        rec.flush()
        rec.disconnect()  # closes the file (footer written): complete when view() returns
    elif spawn:
        rec.spawn(default_blueprint=bp)
        rec.flush()
    return got


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
            frames, previous, first, previous_at = 0, None, None, 0.0
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
