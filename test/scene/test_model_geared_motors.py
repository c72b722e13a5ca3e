"""--geared-motors: an MJCF model's armatures as the geared motors they reflect (docs/models.md,
"The geared motor against the armature"), on Gymnasium's pusher arm (7 hinges, armature 0.04,
test/scene/models/gymnasium/, MIT): the motors are written, the motion tends to the armature's
as the gear grows (the coupling J G = a / G), and the command line takes the option and refuses
bad values in one line."""
from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

pytest.importorskip("mujoco", reason="MuJoCo is the optional extra [models]")

from gyro_sim.dynamics import reference as dyn
from gyro_sim.dynamics.model import compile_model, initial_state
from gyro_sim.scene.load import SceneError, load_scene
from gyro_sim.scene.mjcf import import_model
from test.scene.test_armature_models import CASES, judged


@pytest.fixture(scope="module")
def pusher(tmp_path_factory):
    return judged(CASES["pusher"], tmp_path_factory.mktemp("pusher"))


def _accelerations(scene, y):
    model = compile_model(scene)
    return dyn.forward(model, dyn.Data(model), 0.0, y, np.full(len(model.hinge_bodies), 0.5), None, None)


def test_the_armatures_become_motors(pusher):
    imported = import_model(pusher, geared_motors=10.0)
    joints = [b["joint"] for b in imported.mapping["bodies"] if b["joint"]["type"] == "hinge"]
    assert len(joints) == 7 and all("armature" not in j for j in joints)
    assert all(j["motor"] == {"inertia": pytest.approx(0.04 / 100), "gear": 10.0} for j in joints)
    assert any("as a geared motor of gear 10" in note for note in imported.notes)


def test_the_motion_tends_to_the_armatures_as_the_gear_grows(pusher):
    plain = load_scene(pusher)
    y = initial_state(compile_model(plain))
    ref = _accelerations(plain, y)
    gaps = [np.abs(_accelerations(load_scene(pusher, geared_motors=g), y) - ref).max() / np.abs(ref).max()
            for g in (3.0, 30.0, 3000.0)]
    assert gaps[0] > 1e-3 and gaps[0] > gaps[1] > gaps[2] and gaps[2] < 1e-3


def test_refusals(pusher, tmp_path):
    with pytest.raises(SceneError, match="geared_motors: the gear ratio must be a finite non-zero"):
        load_scene(pusher, geared_motors=0.0)
    with pytest.raises(SceneError, match="geared_motors: only an MJCF model's armatures"):
        load_scene("hinge_chain", geared_motors=10.0)


def test_the_command_line(pusher, tmp_path):
    def run(*extra):
        return subprocess.run([sys.executable, "-m", "gyro_sim.cli", "run", "--scene", str(pusher), "--duration",
                               "0.01", *extra], cwd=tmp_path, capture_output=True, text=True, timeout=300)

    done = run("--geared-motors", "20", "--integrator", "rk4")
    assert done.returncode == 0, done.stderr
    bad = run("--geared-motors", "0")
    assert bad.returncode == 2 and len(bad.stderr.strip().splitlines()) == 1 and "geared_motors" in bad.stderr


CART = """<mujoco><worldbody><body name="cart"><joint name="slider" type="slide" axis="1 0 0" armature="0.3"/>
<geom type="box" size="0.2 0.1 0.1" mass="1"/>
<body name="pole"><joint name="hinge" type="hinge" axis="0 1 0" armature="0.02"/>
<geom type="capsule" fromto="0 0 0 0 0 0.6" size="0.02" mass="0.1"/></body></body></worldbody></mujoco>"""


def test_a_slides_armature_stays_an_armature(tmp_path):
    """A geared motor turns a hinge: a slide's armature is kept as it is, with a note."""
    path = tmp_path / "cart.xml"
    path.write_text(CART)
    imported = import_model(path, geared_motors=10.0)
    cart, pole = (b["joint"] for b in imported.mapping["bodies"])
    assert cart["type"] == "slide" and cart["armature"] == pytest.approx(0.3) and "motor" not in cart
    assert pole["motor"] == {"inertia": pytest.approx(0.02 / 100), "gear": 10.0} and "armature" not in pole
    assert any("a slide's armature 0.3 kept" in note for note in imported.notes)
    load_scene(imported.mapping)
