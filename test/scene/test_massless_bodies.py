"""Massless bodies in a scene (docs/scene-format.md, "Massless bodies"): accepted where what
they carry has inertia about their joint, refused naming the body where not."""
import pytest

from gyro_sim.scene.load import SceneError, load_scene
from test.dynamics.test_massless import INERTIA, ZERO, universal_pendulum


def test_a_massless_frame_is_accepted_with_zero_inertia_in_either_form():
    scene = load_scene(universal_pendulum())
    assert scene.bodies[0].mass == 0.0 and not scene.bodies[0].inertia.any()
    data = universal_pendulum()
    data["bodies"][0].pop("inertia_com")
    data["bodies"][0]["inertia"] = {"axial": 0.0, "transverse": 0.0}
    assert not load_scene(data).bodies[0].inertia.any()


def test_a_massless_body_with_inertia_is_refused():
    data = universal_pendulum()
    data["bodies"][0]["inertia_com"] = INERTIA
    with pytest.raises(SceneError) as info:
        load_scene(data)
    assert info.value.errors == ["bodies[0].inertia_com: must be zero for a massless body (mass 0): a body "
                                 "without mass has no inertia"]


UNDETERMINED = ("bodies[{k}].mass: 0 (a massless frame), and what it carries has no {what} at the initial "
                "state: its joint's acceleration is undetermined; give it a mass, or give what it carries that "
                "inertia")
HINGE = "inertia about its hinge axis"


@pytest.mark.parametrize("case", ["coaxial", "last"])
def test_a_massless_frame_carrying_nothing_about_its_axis_is_refused_naming_it(case):
    data = universal_pendulum()
    bodies = data["bodies"]
    k = 0
    if case == "coaxial":  # the rod turns about the frame's own axis: the frame's angle takes no inertia
        bodies[1]["joint"]["axis"] = [1.0, 0.0, 0.0]
    else:  # nothing after it
        k = 2
        bodies[2].update(mass=0.0, inertia_com=ZERO, com=[0.0, 0.0, 0.0])
    with pytest.raises(SceneError) as info:
        load_scene(data)
    assert info.value.errors == [UNDETERMINED.format(k=k, what=HINGE)]


def test_a_massless_slide_frame_whose_child_slides_along_its_axis_is_refused():
    data = universal_pendulum()
    data["bodies"][0]["joint"] = {"type": "slide", "axis": [1.0, 0.0, 0.0]}
    data["bodies"][0]["initial"] = {"position": 0.1, "velocity": 0.0}
    load_scene(data)  # the rod on its hinge about y: the frame's slide moves its mass
    data["bodies"][1]["joint"] = {"type": "slide", "axis": [2.0, 0.0, 0.0]}
    data["bodies"][1]["initial"] = {"position": 0.0, "velocity": 0.0}
    with pytest.raises(SceneError) as info:
        load_scene(data)
    assert info.value.errors == [UNDETERMINED.format(k=0, what="mass to move along its slide axis")]
