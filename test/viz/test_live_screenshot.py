"""A picture of a live capture (`gyro-sim view --live --save`), taken headless like the log
view's (gyro_sim.viz.rerun_view.screenshot) and looked at pixel by pixel."""
from __future__ import annotations

import signal
import time

import pytest

from test.viz.test_view_screenshot import PLOTS, RERUN, VULKAN, Image, inspect
from test.viz.test_live import START_TIMEOUT, Commander, Live, node, wait_for
from test.viz.test_live import domain  # noqa: F401 (fixture)

pytestmark = [
    pytest.mark.skipif(RERUN is None, reason="the rerun binary (rerun-sdk) is not installed"),
    pytest.mark.skipif(not VULKAN, reason="no Vulkan driver (apt-get install mesa-vulkan-drivers libvulkan1)"),
]
#: wall seconds captured after the first message drawn
CAPTURE_SECONDS = 12
#: palette pixels of one legend entry's dot (measured: 44 at 1200x800), and the fewest of a
#: drawn line (12 s of a 30 s window: about 100 pixels wide)
LEGEND_DOT_PIXELS = 50
MIN_LINE_PIXELS = 80
#: the series of each plot of hinge_chain (test_view_screenshot.PLOTS' order)
SERIES = [3, 3, 2, 1, 3, 2]


def test_screenshot_of_a_live_capture_shows_every_plot_and_the_chain(tmp_path, domain):  # noqa: F811
    from gyro_sim.viz.commands import rerun_binary
    from gyro_sim.viz.rerun_view import screenshot

    d, env, client = domain
    n = node(tmp_path, d)
    try:
        wait_for(lambda: client.node.count_publishers("/joint_states") > 0 or not n.alive(), START_TIMEOUT, "the node")
        cmd = Commander(client)
        rrd = tmp_path / "live.rrd"
        live = Live(tmp_path, env, "--save", rrd)
        # the capture's length counted from the first message drawn, not from the view's start
        # (its discovery of the node takes longer on a busy machine, and the lines would be shorter)
        live.says("receiving from the node", START_TIMEOUT)
        time.sleep(CAPTURE_SECONDS)
        live.proc.send_signal(signal.SIGINT)
        assert live.wait() == 0, live.stderr
        cmd.close()
    finally:
        n.stop()
    png = tmp_path / "live.png"
    screenshot(rerun_binary(), rrd, png, "1200x800")
    assert Image.open(png).size == (1200, 800)
    plots, (count, centre) = inspect(png)
    for name, series, (pixels, _) in zip(PLOTS, SERIES, plots):
        # more than the legend's dots: the lines are drawn, not hidden under the legend
        assert pixels > LEGEND_DOT_PIXELS * series + MIN_LINE_PIXELS, f"plot {name} is empty in {png}: {plots}"
    assert count > 500 and 0.1 < centre < 0.8, f"the chain is not in view ({count} pixels, centre {centre:.2f})"
