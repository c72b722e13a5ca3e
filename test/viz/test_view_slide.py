"""A slide in the views: its body flagged in the chain from the scene (log) and from the URDF
(live, the `slides` of its <gyro_sim> element), its position plotted in m apart from the hinge
angles, its frame carried along its axis by the /tf the Simulator gives."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

rr = pytest.importorskip("rerun")

from gyro_sim import Simulator, load_scene
from gyro_sim.msgs import messages as M
from gyro_sim.scene.urdf import urdf
from gyro_sim.viz.chain import from_scene, from_urdf
from gyro_sim.viz.translate import Translator

from test.dynamics.test_slide import cart_pole
from test.viz.test_robot_view import entities, recording


def test_a_slide_is_plotted_as_a_position_in_both_views(tmp_path):
    scene = load_scene(cart_pole(0.2, 0.5, 0.3, -1.0))
    live, log = from_urdf(urdf(scene)), from_scene(scene)
    assert [b.slide for b in live.bodies] == [b.slide for b in log.bodies] == [True, False]
    sim = Simulator(scene, backend="numpy")
    js = sim.joint_states()
    msg = SimpleNamespace(name=list(js.name), position=list(js.position), velocity=list(js.velocity),
                          effort=list(js.effort))
    drawn = {}
    for name, chain in (("log", log), ("live", None)):
        rec = recording(tmp_path, name)
        tr = Translator(rec, chain)
        if chain is None:
            tr.message(M.ROBOT_DESCRIPTION, 0.0, SimpleNamespace(data=urdf(scene)))
        tr.message(M.JOINT_STATES, 0.0, msg)
        tr.flush()
        rec.flush()
        rec.disconnect()
        drawn[name] = entities(tmp_path / f"{name}.rrd")
    for got in drawn.values():
        assert {"/plots/slide/cart", "/plots/hinge/pole"} <= got and "/plots/hinge/cart" not in got


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_a_slides_frame_moves_along_its_axis(backend):
    e = np.array([1.0, 0.0, 0.5]) / np.linalg.norm([1.0, 0.0, 0.5])
    sim = Simulator(cart_pole(0.2, 0.4, 0.3, 0.0, axis=(1.0, 0.0, 0.5)), backend=backend)
    for _ in range(3):
        d = sim.joint_states().position[0]
        cart, pole = sim.body_states()[:2]
        assert np.allclose(cart.position, d * e, atol=1e-14) and np.allclose(pole.position, d * e, atol=1e-14)
        assert np.allclose(cart.quaternion, [1.0, 0.0, 0.0, 0.0], atol=1e-15)  # it does not turn
        sim.advance(0.2)
    assert abs(d - 0.2) > 0.01
