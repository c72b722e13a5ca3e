"""`gyro-sim view LOG --screenshot`: the picture of a long log shows all of it.

``rerun x.rrd --screenshot-to`` takes its picture 10 frames after start, whatever has been
loaded: with the software renderer, 2 of 5 pictures of a 30 s log had every plot empty and the
chain at its initial pose. The command now waits until the viewer has drawn the whole
recording (gyro_sim.viz.rerun_view.screenshot); these tests look at the pixels.
"""
from __future__ import annotations

import ctypes.util
import glob
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest

from .conftest import gyro_sim

pytest.importorskip("rerun")
Image = pytest.importorskip("PIL.Image")  # a dependency of rerun-sdk

RERUN = str(Path(sys.executable).with_name("rerun")) if Path(sys.executable).with_name("rerun").is_file() else shutil.which("rerun")
VULKAN = ctypes.util.find_library("vulkan") is not None and bool(
    glob.glob("/usr/share/vulkan/icd.d/*.json") + glob.glob("/etc/vulkan/icd.d/*.json"))
pytestmark = [
    pytest.mark.skipif(RERUN is None, reason="the rerun binary (rerun-sdk) is not installed"),
    pytest.mark.skipif(sys.platform.startswith("linux") and not VULKAN,
                       reason="no Vulkan driver (apt-get install mesa-vulkan-drivers libvulkan1)"),
]

#: the plots' series colours (rerun_view.PALETTE, the first six)
PALETTE = [(0, 114, 178), (230, 159, 0), (0, 158, 115), (204, 121, 167), (86, 180, 233), (213, 94, 0)]
BODY = (70, 130, 180)
#: the plots of hinge_chain, in the grid's order (two columns, left to right, top to bottom)
PLOTS = ["euler arm1", "euler arm2", "hinge", "rotor_rate", "axis_moments", "drift"]
#: the plots' grid takes the right half of the picture, in this many rows and columns
GRID_ROWS, GRID_COLUMNS = 3, 2


def _near(a, color, tol):
    return np.abs(a - np.array(color)).sum(-1) < tol


def inspect(png):
    """Per plot (grid order): (palette pixels, rightmost one as a fraction of the plot's
    width); and the chain's bodies in the 3D view: (pixels, mean height as a fraction of the view)."""
    a = np.asarray(Image.open(png).convert("RGB")).astype(int)
    h, w, _ = a.shape
    right = a[int(0.05 * h):int(0.96 * h), int(0.5 * w):]
    lines = np.zeros(right.shape[:2], bool)
    for c in PALETTE:
        lines |= _near(right, c, 60)
    plots = []
    for band in np.array_split(lines, GRID_ROWS, axis=0):
        for cell in np.array_split(band, GRID_COLUMNS, axis=1):
            xs = np.nonzero(cell)[1]
            plots.append((int(cell.sum()), float(xs.max()) / cell.shape[1] if xs.size else 0.0))
    view = a[int(0.05 * h):int(0.96 * h), :int(0.48 * w)]
    ys = np.nonzero(_near(view, BODY, 60))[0]
    return plots[:len(PLOTS)], (ys.size, float(ys.mean()) / view.shape[0] if ys.size else 1.0)


def _headless_viewers() -> set[int]:
    """pids of running rerun viewers started headless (as the screenshot does)."""
    out = set()
    for d in Path("/proc").glob("[0-9]*"):
        try:
            argv = (d / "cmdline").read_bytes().split(b"\0")
        except OSError:
            continue
        if b"--headless" in argv and any(a.endswith(b"rerun") for a in argv[:1]):
            out.add(int(d.name))
    return out


def test_the_viewer_started_is_the_binary_not_the_python_wrapper():
    """A venv's `rerun` is a Python script that runs the binary as its child: stopping the script
    left the headless viewer running after every screenshot (found after a test run)."""
    from gyro_sim.viz.commands import rerun_binary

    exe = Path(rerun_binary())
    assert not exe.read_bytes()[:2] == b"#!", f"{exe} is a script"


@pytest.mark.slow
def test_screenshot_of_a_30_s_log_shows_every_plot_and_the_chain(tmp_path):
    log = tmp_path / "v30.mcap"
    commands = tmp_path / "commands.yaml"  # steps on every axis: no plot is a flat line
    commands.write_text("- [0.0, [0.002, 0.05, -0.03]]\n- [10.0, [-0.002, -0.05, 0.03]]\n- [20.0, [0.0, 0.02, 0.0]]\n")
    r = gyro_sim("run", "--scene", "hinge_chain", "--duration", 30, "--commands", commands, "--record", log,
                 timeout=300)
    assert r.returncode == 0, r.stderr
    pngs = []
    before = _headless_viewers()
    for k in range(2):
        png = tmp_path / f"shot{k}.png"
        r = gyro_sim("view", log, "--screenshot", png, "--window-size", "1200x800", timeout=300)
        assert r.returncode == 0, r.stderr
        assert Image.open(png).size == (1200, 800)
        plots, chain = inspect(png)
        for name, (count, rightmost) in zip(PLOTS, plots):
            # an empty plot has none (its legend neither)
            assert count > 250, f"plot {name} is empty in {png}: {plots}"
            # drawn to the end of the log (the time axis has 4 % room after it)
            assert rightmost > 0.9, f"plot {name} stops at {rightmost:.2f} of its width: {plots}"
        # the bodies are drawn, around the middle of the view where the camera looks (a picture
        # taken before the data: a stub of the initial pose at the bottom edge)
        count, centre = chain
        assert count > 500 and 0.15 < centre < 0.75, f"the chain is not in view ({count} pixels, centre {centre:.2f})"
        pngs.append(png)
    # the picture is taken once all is drawn, at the end of the log: the same picture each time
    assert pngs[0].read_bytes() == pngs[1].read_bytes()
    assert _headless_viewers() <= before, "a headless viewer was left running"
