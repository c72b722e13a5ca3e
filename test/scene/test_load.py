"""Tests of the scene loader (docs/scene-format.md): shipped scenes, round trips, and refusals."""
from __future__ import annotations

import copy
import dataclasses
import math
import os
import re
import threading
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

from gyro_sim.scene.records import Scene
from gyro_sim.scene.load import SceneError, load_scene
from gyro_sim.paths import NOT_SCENES

CONFIG = Path(__file__).resolve().parents[2] / "config"
SCENE_FILES = sorted(p for p in CONFIG.glob("*.yaml") if p.name not in NOT_SCENES)

# A valid scene using every feature: both inertia forms, both initial forms of a spherical
# joint, a hinge, torque and speed rotors, visual, a fixed base with a position.
VALID = {
    "name": "test chain",
    "gravity": [0.0, 0.0, -9.81],
    "base": {"type": "fixed", "position": [0.0, 0.0, 1.0]},
    "bodies": [
        {
            "name": "arm1",
            "joint": {"type": "spherical"},
            "mass": 0.5,
            "com": [0.0, 0.0, 0.1],
            "inertia": {"axial": 1.0e-4, "transverse": 6.7e-3},
            "next_joint": [0.0, 0.0, 0.2],
            "rotors": [
                {"name": "wheel1", "axis": [0.0, 0.0, 2.0], "position": [0.0, 0.0, 0.1],
                 "mass": 0.1, "axial_inertia": 4.5e-5, "transverse_inertia": 2.4e-5,
                 "mode": "torque", "spin": 100.0, "actuated": True},
            ],
            "initial": {"euler": [0.0, 0.5, 0.0], "euler_rates": [1.0, 0.0, 0.0]},
            "visual": {"radius": 0.02},
        },
        {
            "name": "arm2",
            "joint": {"type": "spherical"},
            "mass": 0.3,
            "com": [0.0, 0.0, 0.075],
            "inertia_com": [[6.5e-4, 0.0, 0.0], [0.0, 6.8e-4, 0.0], [0.0, 0.0, 5.0e-5]],
            "next_joint": [0.0, 0.0, 0.15],
            "rotors": [
                {"name": "motor2", "axis": [1, 0, 0], "mass": 0.05, "axial_inertia": 2.0e-5,
                 "transverse_inertia": 1.1e-5, "mode": "speed", "spin": 50},
            ],
            "initial": {"quaternion": [2.0, 0.0, 0.0, 0.0], "angular_velocity": [0.0, 0.5, 0.0]},
        },
        {
            "name": "arm3",
            "joint": {"type": "hinge", "axis": [3.0, 4.0, 0.0]},
            "mass": 0.2,
            "com": [0.0, 0.0, 0.06],
            "inertia": {"axial": 2.25e-5, "transverse": 9.7e-4},
            "initial": {"angle": 0.3, "rate": -1.0},
        },
    ],
}

PATH_TOKEN = re.compile(r"([A-Za-z_]\w*)|\[(\d+)\]")


def _walk(data, path):
    """(container, last key) for a key path written like the loader's messages."""
    keys = [name if name else int(index) for name, index in PATH_TOKEN.findall(path)]
    for key in keys[:-1]:
        data = data[key]
    return data, keys[-1]


def put(path, value):
    def mutate(data):
        container, key = _walk(data, path)
        container[key] = copy.deepcopy(value)
    return mutate


def drop(path):
    def mutate(data):
        container, key = _walk(data, path)
        del container[key]
    return mutate


def both(*mutations):
    def mutate(data):
        for mutation in mutations:
            mutation(data)
    return mutate


def valid():
    return copy.deepcopy(VALID)


def assert_same(a, b, where="scene"):
    """Field-by-field equality of scene records (numpy arrays compared exactly)."""
    if dataclasses.is_dataclass(a):
        assert type(a) is type(b), where
        for f in dataclasses.fields(a):
            if f.compare and f.name != "path":
                assert_same(getattr(a, f.name), getattr(b, f.name), f"{where}.{f.name}")
    elif isinstance(a, tuple):
        assert isinstance(b, tuple) and len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b)):
            assert_same(x, y, f"{where}[{i}]")
    elif isinstance(a, np.ndarray):
        assert isinstance(b, np.ndarray) and a.dtype == b.dtype == float, where
        np.testing.assert_array_equal(a, b, err_msg=where)
    else:
        assert a == b, f"{where}: {a!r} != {b!r}"


def arrays_of(record):
    """Every numpy array held by a scene record, recursively."""
    if isinstance(record, np.ndarray):
        yield record
    elif dataclasses.is_dataclass(record):
        for f in dataclasses.fields(record):
            if f.name != "source":
                yield from arrays_of(getattr(record, f.name))
    elif isinstance(record, tuple):
        for item in record:
            yield from arrays_of(item)


# ---------------------------------------------------------------------------------------------
# Valid scenes


@pytest.mark.parametrize("path", SCENE_FILES, ids=[p.name for p in SCENE_FILES])
def test_shipped_scene_loads(path):
    scene = load_scene(path)
    assert isinstance(scene, Scene)
    assert scene.path == str(path)
    assert scene.bodies and scene.name
    for array in arrays_of(scene):
        assert not array.flags.writeable
        assert np.all(np.isfinite(array))
    for body in scene.bodies:
        assert np.allclose(body.inertia, body.inertia.T)
        assert np.all(np.linalg.eigvalsh(body.inertia) > 0)
        for rotor in body.rotors:
            assert math.isclose(np.linalg.norm(rotor.axis), 1.0)


def test_shipped_scenes_cover_the_spec():
    names = {p.name for p in SCENE_FILES}
    assert {"chain_4.yaml", "hinge_chain.yaml", "free_chain_rotors.yaml", "vibrating_base.yaml",
            "fast_rotor.yaml", "light_tip.yaml", "speed_rotor_top.yaml"} <= names


def test_kapitza_scene_is_above_the_stability_threshold():
    scene = load_scene(CONFIG / "vibrating_base.yaml")
    (body,) = scene.bodies
    g = float(np.linalg.norm(scene.gravity))
    a = float(np.linalg.norm(scene.base.amplitude))
    omega = 2 * math.pi * scene.base.frequency
    inertia = body.inertia[0, 0]  # transverse, about the suspension point
    c = float(np.linalg.norm(body.com))
    assert (a * omega) ** 2 > 2 * g * inertia / (body.mass * c)
    assert abs(body.initial.euler[1] - math.pi) < 0.1


def test_light_tip_mass_ratio():
    scene = load_scene(CONFIG / "light_tip.yaml")
    assert len(scene.bodies) == 3
    assert math.isclose(scene.bodies[2].mass / scene.bodies[1].mass, 1e-6)


def test_hinge_chain_is_the_eq_52_case():
    scene = load_scene(CONFIG / "hinge_chain.yaml")
    types = [body.joint.type for body in scene.bodies]
    assert types == ["spherical", "spherical", "hinge", "hinge"]
    axis3, axis4 = scene.bodies[2].joint.axis, scene.bodies[3].joint.axis
    assert np.linalg.norm(np.cross(axis3, axis4)) > 0.5
    rotors = [rotor for body in scene.bodies for rotor in body.rotors]
    assert any(rotor.actuated and rotor.mode == "torque" for rotor in rotors)
    assert scene.gravity is not None and scene.base.type == "fixed"


def test_free_chain_and_rotor_scenes():
    free = load_scene(CONFIG / "free_chain_rotors.yaml")
    assert free.base.type == "free" and free.gravity is None
    assert np.linalg.norm(free.base.velocity) > 0
    assert [b.joint.type for b in free.bodies] == ["spherical", "spherical", "hinge"]
    assert all(body.rotors for body in free.bodies)
    assert {r.mode for b in free.bodies for r in b.rotors} == {"torque", "speed"}
    (fast,) = load_scene(CONFIG / "fast_rotor.yaml").bodies[0].rotors
    assert (fast.mode, fast.spin) == ("torque", 2000.0)
    (motor,) = load_scene(CONFIG / "speed_rotor_top.yaml").bodies[0].rotors
    assert (motor.mode, motor.spin) == ("speed", 150.0)


def test_dict_and_yaml_give_equal_scenes(tmp_path):
    path = tmp_path / "scene.yaml"
    path.write_text(yaml.safe_dump(VALID), encoding="utf-8")
    from_dict = load_scene(valid())
    from_file = load_scene(path)
    assert_same(from_dict, from_file)
    assert from_dict.source == from_file.source == VALID
    assert from_dict.path is None and from_file.path == str(path)


def test_values_are_converted_and_normalised():
    scene = load_scene(valid())
    arm1, arm2, arm3 = scene.bodies
    np.testing.assert_array_equal(scene.gravity, [0.0, 0.0, -9.81])
    assert scene.base.type == "fixed" and scene.base.velocity is None
    np.testing.assert_array_equal(arm1.rotors[0].axis, [0.0, 0.0, 1.0])
    assert arm1.rotors[0].actuated and not arm2.rotors[0].actuated
    assert arm2.rotors[0].spin == 50.0 and isinstance(arm2.rotors[0].spin, float)
    np.testing.assert_array_equal(arm2.rotors[0].position, np.zeros(3))
    np.testing.assert_array_equal(arm2.initial.quaternion, [1.0, 0.0, 0.0, 0.0])
    assert arm2.initial.euler is None
    np.testing.assert_allclose(arm3.joint.axis, [0.6, 0.8, 0.0])
    assert arm3.next_joint is None and arm3.initial.euler is None
    assert (arm3.initial.angle, arm3.initial.rate) == (0.3, -1.0)
    assert arm1.visual_radius == 0.02 and arm2.visual_radius is None
    np.testing.assert_array_equal(arm1.inertia, np.diag([6.7e-3, 6.7e-3, 1.0e-4]))


def test_defaults():
    data = valid()
    del data["gravity"], data["base"]["position"], data["bodies"][0]["initial"]
    del data["bodies"][0]["com"], data["bodies"][2]["initial"], data["bodies"][0]["rotors"]
    data["bodies"][0]["inertia"] = {"axial": 1e-3, "transverse": 1e-3}
    scene = load_scene(data)
    assert scene.gravity is None
    np.testing.assert_array_equal(scene.base.position, np.zeros(3))
    first = scene.bodies[0]
    np.testing.assert_array_equal(first.com, np.zeros(3))
    assert first.rotors == ()
    np.testing.assert_array_equal(first.initial.euler, np.zeros(3))
    np.testing.assert_array_equal(first.initial.euler_rates, np.zeros(3))
    assert first.initial.quaternion is None
    assert (scene.bodies[2].initial.angle, scene.bodies[2].initial.rate) == (0.0, 0.0)


def test_zero_gravity_is_kept():
    data = valid()
    data["gravity"] = [0, 0, 0]
    np.testing.assert_array_equal(load_scene(data).gravity, np.zeros(3))


def test_moving_and_free_bases():
    data = valid()
    data["base"] = {"type": "moving", "motion": {"type": "sine", "amplitude": [0, 0, 0.01],
                                                 "frequency": 50}}
    base = load_scene(data).base
    assert base.frequency == 50.0
    np.testing.assert_array_equal(base.amplitude, [0.0, 0.0, 0.01])
    data["base"] = {"type": "free"}
    base = load_scene(data).base
    np.testing.assert_array_equal(base.velocity, np.zeros(3))
    assert base.amplitude is None and base.frequency is None


def test_inertia_forms_agree():
    # A uniform cylinder, com off the axis so that the parallel-axis term is a full tensor.
    m, radius, length = 0.5, 0.02, 0.2
    a_com = m * radius**2 / 2
    b_com = m * (3 * radius**2 + length**2) / 12
    com = np.array([0.0, 0.0, 0.1])
    data = valid()
    body = data["bodies"][0]
    body["com"] = com.tolist()
    body["inertia"] = {"axial": a_com, "transverse": b_com + m * 0.1**2}
    about_origin = load_scene(data).bodies[0].inertia
    del body["inertia"]
    body["inertia_com"] = np.diag([b_com, b_com, a_com]).tolist()
    from_com = load_scene(data).bodies[0].inertia
    np.testing.assert_allclose(from_com, about_origin, rtol=1e-12, atol=0)

    body["com"] = [0.01, -0.02, 0.1]
    c = np.array(body["com"])
    expected = np.diag([b_com, b_com, a_com]) + m * (c @ c * np.eye(3) - np.outer(c, c))
    np.testing.assert_allclose(load_scene(data).bodies[0].inertia, expected, rtol=1e-14)


def test_records_are_immutable():
    scene = load_scene(valid())
    with pytest.raises(ValueError):
        scene.bodies[0].com[0] = 1.0
    with pytest.raises(ValueError):
        scene.bodies[0].inertia[0, 0] = 1.0
    with pytest.raises(dataclasses.FrozenInstanceError):
        scene.bodies[0].mass = 2.0  # type: ignore[misc]


def test_source_is_a_plain_deep_copy():
    data = valid()
    data["bodies"][0]["com"] = np.array([0.0, 0.0, 0.1])
    data["bodies"][0]["mass"] = np.float64(0.5)
    scene = load_scene(data)
    data["bodies"][0]["name"] = "changed"
    assert scene.source["bodies"][0]["name"] == "arm1"
    assert scene.source["bodies"][0]["com"] == [0.0, 0.0, 0.1]
    assert type(scene.source["bodies"][0]["mass"]) is float
    yaml.safe_dump(scene.source)  # embeddable in a log as plain YAML


def test_yaml_reads_exponents_without_a_dot(tmp_path):
    path = tmp_path / "scene.yaml"
    text = yaml.safe_dump(VALID).replace("mass: 0.2", "mass: 2e-1")
    assert "2e-1" in text
    path.write_text(text, encoding="utf-8")
    assert load_scene(path).bodies[2].mass == 0.2


# ---------------------------------------------------------------------------------------------
# Refusals: a valid scene plus one mutation, and the (key path, rule) it must be refused with

MOVING = {"type": "moving", "motion": {"type": "sine", "amplitude": [0, 0, 0.01], "frequency": 5}}
HINGE_X = {"type": "hinge", "axis": [1, 0, 0]}
NON_PD = [[1e-3, 0, 0], [0, 1e-3, 0], [0, 0, -1e-4]]

MALFORMED = [
    # masses and numbers
    ("negative mass", put("bodies[2].mass", -1.0), "bodies[2].mass", "must be >= 0 (got -1.0)"),
    ("zero mass with an inertia", put("bodies[0].mass", 0), "bodies[0].inertia", "must be zero for a massless body"),
    ("string number", put("bodies[0].mass", "heavy"), "bodies[0].mass", "must be a number"),
    ("numeric string", put("bodies[0].mass", "0.5"), "bodies[0].mass", "must be a number"),
    ("NaN", put("gravity", [0.0, 0.0, float("nan")]), "gravity[2]", "must be finite"),
    ("inf", put("bodies[1].mass", float("inf")), "bodies[1].mass", "must be finite"),
    ("bool number", put("bodies[0].mass", True), "bodies[0].mass", "not a boolean"),
    ("bool in vector", put("bodies[0].com", [0, False, 0.1]), "bodies[0].com[1]",
     "not a boolean"),
    ("null required", put("bodies[0].mass", None), "bodies[0].mass", "required"),
    # vectors
    ("short vector", put("bodies[0].com", [0.0, 0.1]), "bodies[0].com",
     "must have 3 components (got 2)"),
    ("long vector", put("base.position", [0, 0, 0, 0]), "base.position", "must have 3"),
    ("scalar vector", put("gravity", -9.81), "gravity", "must be a list of 3 numbers"),
    ("zero hinge axis", put("bodies[2].joint.axis", [0, 0, 0]), "bodies[2].joint.axis",
     "zero vector"),
    ("zero rotor axis", put("bodies[0].rotors[0].axis", [0.0, 0.0, 0.0]),
     "bodies[0].rotors[0].axis", "zero vector"),
    # inertia
    ("non-PD inertia_com", put("bodies[1].inertia_com", NON_PD), "bodies[1].inertia_com",
     "not positive definite"),
    ("asymmetric inertia_com", put("bodies[1].inertia_com[0][1]", 1e-5),
     "bodies[1].inertia_com", "not symmetric"),
    ("triangle inertia_com", put("bodies[1].inertia_com", np.diag([1e-4, 1e-4, 3e-4]).tolist()),
     "bodies[1].inertia_com", "triangle inequality"),
    ("inertia_com shape", put("bodies[1].inertia_com", [[1e-3, 0, 0], [0, 1e-3, 0]]),
     "bodies[1].inertia_com", "must have 3 rows"),
    ("triangle axial", put("bodies[0].inertia", {"axial": 0.02, "transverse": 6.7e-3}),
     "bodies[0].inertia", "triangle inequality"),
    ("impossible com", put("bodies[0].inertia", {"axial": 1e-4, "transverse": 4e-3}),
     "bodies[0].inertia", "impossible mass distribution"),
    ("negative axial", put("bodies[0].inertia.axial", -1e-4), "bodies[0].inertia.axial",
     "must be > 0"),
    ("both inertia forms", put("bodies[1].inertia", {"axial": 1e-4, "transverse": 1e-3}),
     "bodies[1]", "inertia and inertia_com both given"),
    ("no inertia", drop("bodies[2].inertia"), "bodies[2].inertia", "required"),
    # unknown keys, at every level
    ("unknown top key", put("frobnicate", 1), "frobnicate", "unknown key"),
    ("unknown base key", put("base.frobnicate", 1), "base.frobnicate", "unknown key"),
    ("unknown motion key", both(put("base", MOVING), put("base.motion.phase", 0.0)),
     "base.motion.phase", "unknown key"),
    ("unknown body key", put("bodies[0].frobnicate", 1), "bodies[0].frobnicate", "unknown key"),
    ("misspelt body key", put("bodies[0].mas", 1), "bodies[0].mas", "did you mean 'mass'"),
    ("unknown joint key", put("bodies[0].joint.limit", 1), "bodies[0].joint.limit",
     "unknown key"),
    ("unknown inertia key", put("bodies[0].inertia.polar", 1), "bodies[0].inertia.polar",
     "unknown key"),
    ("unknown rotor key", put("bodies[0].rotors[0].colour", "red"),
     "bodies[0].rotors[0].colour", "unknown key"),
    ("unknown initial key", put("bodies[0].initial.omega", [0, 0, 0]),
     "bodies[0].initial.omega", "unknown key"),
    ("unknown visual key", put("bodies[0].visual.colour", "red"), "bodies[0].visual.colour",
     "unknown key"),
    ("non-string key", put("bodies[0].visual", {"radius": 0.02, 1: 2}), "bodies[0].visual.1",
     "unknown key"),
    # chain structure
    ("missing next_joint", drop("bodies[1].next_joint"), "bodies[1].next_joint",
     "required on every body but the last"),
    ("next_joint on last", put("bodies[2].next_joint", [0, 0, 0.1]), "bodies[2].next_joint",
     "not allowed on the last body"),
    ("hinge first on free base",
     both(put("base", {"type": "free"}), put("bodies[0].joint", HINGE_X),
          put("bodies[0].initial", {"angle": 0.0})),
     "bodies[0].joint.type", "free base's first joint must be spherical"),
    ("empty bodies", put("bodies", []), "bodies", "must not be empty"),
    ("bodies not a list", put("bodies", {"name": "arm1"}), "bodies", "must be a list"),
    ("body not a mapping", put("bodies[1]", "arm2"), "bodies[1]", "must be a mapping"),
    # joints
    ("bad joint type", put("bodies[0].joint.type", "ball"), "bodies[0].joint.type",
     "must be one of spherical, hinge, slide (got 'ball')"),
    ("hinge without axis", drop("bodies[2].joint.axis"), "bodies[2].joint.axis",
     "required for a hinge"),
    ("axis on spherical", put("bodies[0].joint.axis", [0, 0, 1]), "bodies[0].joint.axis",
     "not allowed for a spherical joint"),
    # names
    ("missing name", drop("name"), "name", "required key missing"),
    ("empty scene name", put("name", "  "), "name", "must not be empty"),
    ("missing body name", drop("bodies[1].name"), "bodies[1].name", "required key missing"),
    ("duplicate body names", put("bodies[1].name", "arm1"), "bodies[1].name", "duplicate name"),
    ("body and rotor share a name", put("bodies[1].rotors[0].name", "arm3"),
     "bodies[2].name", "duplicate name 'arm3'"),
    ("name with a space", put("bodies[0].name", "arm 1"), "bodies[0].name",
     "must not contain whitespace"),
    ("name with a slash", put("bodies[0].name", "arm/1"), "bodies[0].name",
     "must not contain whitespace, '/'"),
    ("names making one wrench topic", both(put("bodies[0].name", "arm_1"), put("bodies[1].name", "arm-1")),
     "bodies[1].name", "make the same topic ~/wrench/arm_1"),
    ("joint-state name clash", put("bodies[0].rotors[0].name", "arm2_theta"),
     "bodies[1].name", "joint-state name 'arm2_theta'"),
    # base
    ("bad base type", put("base.type", "floating"), "base.type",
     "must be one of fixed, moving, free (got 'floating')"),
    ("missing base", drop("base"), "base", "required key missing"),
    ("moving without motion", put("base.type", "moving"), "base.motion",
     "required for a moving base"),
    ("zero frequency", both(put("base", MOVING), put("base.motion.frequency", 0.0)),
     "base.motion.frequency", "must be > 0"),
    ("negative frequency", both(put("base", MOVING), put("base.motion.frequency", -5)),
     "base.motion.frequency", "must be > 0"),
    ("bad motion type", both(put("base", MOVING), put("base.motion.type", "square")),
     "base.motion.type", "must be one of sine"),
    ("motion on fixed base", put("base.motion", MOVING["motion"]), "base.motion",
     "not allowed for a fixed base"),
    ("velocity on fixed base", put("base.velocity", [0, 0, 0]), "base.velocity",
     "not allowed for a fixed base"),
    ("velocity on moving base", both(put("base", MOVING), put("base.velocity", [0, 0, 0])),
     "base.velocity", "not allowed for a moving base"),
    # initial states
    ("mixed initial forms", put("bodies[0].initial.quaternion", [1, 0, 0, 0]),
     "bodies[0].initial", "mixes the Euler form"),
    ("hinge initial on spherical", put("bodies[0].initial.angle", 0.1),
     "bodies[0].initial.angle", "not allowed on a spherical joint"),
    ("spherical initial on hinge", put("bodies[2].initial.euler", [0, 0, 0]),
     "bodies[2].initial.euler", "not allowed on a hinge joint"),
    ("zero quaternion", put("bodies[1].initial.quaternion", [0, 0, 0, 0]),
     "bodies[1].initial.quaternion", "zero vector"),
    ("short quaternion", put("bodies[1].initial.quaternion", [1, 0, 0]),
     "bodies[1].initial.quaternion", "must have 4 components (got 3)"),
    ("angular velocity alone", drop("bodies[1].initial.quaternion"),
     "bodies[1].initial.quaternion", "required with angular_velocity"),
    ("string hinge angle", put("bodies[2].initial.angle", "30 deg"), "bodies[2].initial.angle",
     "must be a number"),
    # rotors
    ("actuated speed rotor", put("bodies[1].rotors[0].actuated", True),
     "bodies[1].rotors[0].actuated", "a speed rotor's rate is prescribed"),
    ("rotor 2B < A", put("bodies[0].rotors[0].transverse_inertia", 2.0e-5),
     "bodies[0].rotors[0].transverse_inertia", "2 B_i >= A_i"),
    ("rotor bad mode", put("bodies[0].rotors[0].mode", "sped"), "bodies[0].rotors[0].mode",
     "must be one of torque, speed (got 'sped')"),
    ("rotor negative mass", put("bodies[0].rotors[0].mass", -0.1), "bodies[0].rotors[0].mass",
     "must be >= 0"),
    ("rotor zero axial inertia", put("bodies[0].rotors[0].axial_inertia", 0.0),
     "bodies[0].rotors[0].axial_inertia", "must be > 0"),
    ("rotor missing mode", drop("bodies[0].rotors[0].mode"), "bodies[0].rotors[0].mode",
     "required key missing"),
    ("actuated not a bool", put("bodies[0].rotors[0].actuated", "yes"),
     "bodies[0].rotors[0].actuated", "must be true or false"),
    ("rotors not a list", put("bodies[0].rotors", {"name": "wheel1"}), "bodies[0].rotors",
     "must be a list"),
    # visual
    ("zero visual radius", put("bodies[0].visual.radius", 0.0), "bodies[0].visual.radius",
     "must be > 0"),
]


@pytest.mark.parametrize("mutate, path, rule", [m[1:] for m in MALFORMED],
                         ids=[m[0] for m in MALFORMED])
def test_malformed_scene_is_refused(mutate, path, rule):
    data = valid()
    mutate(data)
    with pytest.raises(SceneError) as info:
        load_scene(data)
    errors = info.value.errors
    assert any(e.startswith(f"{path}: ") and rule in e for e in errors), errors
    assert all(e in str(info.value) for e in errors)


def test_scene_error_is_a_value_error():
    assert issubclass(SceneError, ValueError)
    with pytest.raises(ValueError):
        load_scene({"name": "x"})


def test_scene_not_a_mapping(tmp_path):
    with pytest.raises(SceneError, match="scene: must be a file path or a mapping"):
        load_scene([VALID])  # type: ignore[arg-type]
    path = tmp_path / "list.yaml"
    path.write_text("- name: x\n", encoding="utf-8")
    with pytest.raises(SceneError, match="scene: must be a mapping"):
        load_scene(path)


def test_all_errors_reported_at_once():
    data = valid()
    data["bodies"][2]["mass"] = -1.0
    data["bodies"][2]["joint"]["axis"] = [0, 0, 0]
    data["bodies"][1]["inertia_com"] = NON_PD
    data["bodies"][0]["rotors"][0]["mode"] = "sped"
    data["bodies"][0]["frobnicate"] = 1
    data["base"]["velocity"] = [0, 0, 0]
    with pytest.raises(SceneError) as info:
        load_scene(data)
    expected = [
        "base.velocity: not allowed for a fixed base",
        "bodies[0].frobnicate: unknown key",
        "bodies[0].rotors[0].mode: must be one of torque, speed (got 'sped')",
        "bodies[1].inertia_com: not positive definite",
        "bodies[2].joint.axis: zero vector",
        "bodies[2].mass: must be >= 0 (got -1.0)",
    ]
    errors = info.value.errors
    assert len(errors) == len(expected), errors
    for item in expected:
        assert any(e.startswith(item) for e in errors), (item, errors)
    message_lines = str(info.value).splitlines()
    assert len(message_lines) == 1 + len(expected)  # a header, then one error per line


def test_values_checked_even_when_the_type_is_bad():
    data = valid()
    data["base"] = {"type": "flying", "velocity": [1, 2]}
    data["bodies"][2]["joint"]["type"] = "slider"
    data["bodies"][2]["initial"]["angle"] = "x"
    with pytest.raises(SceneError) as info:
        load_scene(data)
    errors = info.value.errors
    for path in ("base.type", "base.velocity", "bodies[2].joint.type", "bodies[2].initial.angle"):
        assert any(e.startswith(path + ": ") for e in errors), (path, errors)


def test_yaml_syntax_error(tmp_path):
    path = tmp_path / "broken.yaml"
    path.write_text("name: broken\nbodies: [\n  - {name: a\n", encoding="utf-8")
    with pytest.raises(SceneError) as info:
        load_scene(path)
    assert str(path) in str(info.value)
    assert "YAML error at line" in str(info.value)
    assert info.value.path == str(path)


def test_yaml_duplicate_key(tmp_path):
    path = tmp_path / "duplicate.yaml"
    path.write_text(yaml.safe_dump(VALID) + "name: again\n", encoding="utf-8")
    with pytest.raises(SceneError, match="duplicate key 'name'"):
        load_scene(path)


def test_empty_yaml_file(tmp_path):
    path = tmp_path / "empty.yaml"
    path.write_text("# nothing here\n", encoding="utf-8")
    with pytest.raises(SceneError, match="must be a mapping"):
        load_scene(path)


def test_missing_file(tmp_path):
    path = tmp_path / "nowhere.yaml"
    with pytest.raises(SceneError) as info:
        load_scene(path)
    assert f"{path}: file not found" in str(info.value)


def test_directory_is_not_a_scene(tmp_path):
    with pytest.raises(SceneError, match="is a directory"):
        load_scene(tmp_path)


# --- crafted input: bounded ------------------------------------------------------------------


def test_deeply_nested_yaml_is_refused_with_a_scene_error(tmp_path):
    path = tmp_path / "deep.yaml"
    path.write_text("name: deep\nbase: {type: fixed}\nbodies: " + "[" * 100_000 + "]" * 100_000 + "\n")
    with pytest.raises(SceneError, match="nested deeper than"):
        load_scene(path)


def test_alias_expansion_is_bounded(tmp_path):
    # nine levels of nine aliases: 9^9 nodes once expanded (a "billion laughs")
    lines = ["a0: &a0 [x, x, x, x, x, x, x, x, x]"]
    lines += [f"a{i}: &a{i} [" + ", ".join([f"*a{i - 1}"] * 9) + "]" for i in range(1, 10)]
    path = tmp_path / "laughs.yaml"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(SceneError, match="more than .* nodes"):
        load_scene(path)


def test_anchors_and_aliases_within_the_bounds_still_load(tmp_path):
    text = yaml.safe_dump(valid(), sort_keys=False, default_flow_style=True, width=10**6)
    text = text.replace("com: [0.0, 0.0, 0.1]", "com: &c [0.0, 0.0, 0.1]", 1)
    text = text.replace("position: [0.0, 0.0, 0.1]", "position: *c", 1)
    assert "*c" in text and "&c" in text
    path = tmp_path / "aliased.yaml"
    path.write_text(text)
    scene = load_scene(path)
    assert list(scene.bodies[0].rotors[0].position) == [0.0, 0.0, 0.1]


@pytest.mark.parametrize("path, value, bound", [
    ("bodies[0].mass", 1e308, "1e+09 kg"),
    ("bodies[1].inertia_com", [[1e308, 0, 0], [0, 1e308, 0], [0, 0, 1e308]], "1e+12 kg m^2"),
    ("bodies[0].inertia.axial", 1e300, "1e+12 kg m^2"),
    ("bodies[0].com", [0.0, 0.0, 1e200], "10000 m"),
    ("bodies[0].rotors[0].spin", 1e30, "1e+07 rad/s"),
    ("gravity", [0.0, 0.0, -1e12], "10000 m/s^2"),
])
def test_numbers_beyond_the_physical_sanity_bounds_are_refused(path, value, bound):
    data = valid()
    put(path, value)(data)
    with pytest.raises(SceneError) as info:
        load_scene(data)
    text = str(info.value)
    assert path in text and bound in text, text


def test_inertia_com_1e308_gives_a_scene_error_not_linalg_error():
    data = valid()
    put("bodies[1].inertia_com", [[1e308, 1e308, 1e308]] * 3)(data)
    with pytest.raises(SceneError, match="sanity bound of inertia_com"):
        load_scene(data)


def test_a_name_rclpy_would_refuse_as_a_topic_is_refused_by_the_loader():
    data = valid()
    long = "a" * 300
    put("bodies[0].name", long)(data)
    with pytest.raises(SceneError, match=r"bodies\[0\]\.name: at most 64 characters \(got 300\)"):
        load_scene(data)
    put("bodies[0].name", "a" * 64)(data)
    load_scene(data)


def test_the_name_limit_is_within_what_ros_accepts_for_a_wrench_topic():
    """The loader's limit against the real one: a topic ~/wrench/<name> of a node gyro_sim."""
    rclpy = pytest.importorskip("rclpy")
    from rclpy.validate_full_topic_name import validate_full_topic_name

    from gyro_sim.scene.names import MAX_NAME_LENGTH

    validate_full_topic_name("/gyro_sim/wrench/" + "a" * MAX_NAME_LENGTH)
    with pytest.raises(rclpy.exceptions.InvalidTopicNameException):
        validate_full_topic_name("/gyro_sim/wrench/" + "a" * 300)


# --- long scenes load; hostile files are refused, quickly and in one line ----------------------

#: what "quickly" means for a refusal: the bounds are checked before anything is built
REFUSAL_SECONDS = 5.0


def long_chain(n: int) -> dict:
    """A chain of `n` rods on spherical joints, each with a rotor (every key a body can have)."""
    bodies = []
    for k in range(n):
        body = {"name": f"link{k}", "joint": {"type": "spherical"}, "mass": 0.2, "com": [0.0, 0.0, 0.05],
                "inertia": {"axial": 1e-4, "transverse": 7e-4},
                "rotors": [{"name": f"rotor{k}", "axis": [0.0, 0.0, 1.0], "position": [0.0, 0.0, 0.05],
                            "mass": 0.01, "axial_inertia": 1e-6, "transverse_inertia": 6e-7,
                            "mode": "torque", "spin": 10.0}],
                "initial": {"euler": [0.01 * k, 0.1, 0.0], "euler_rates": [0.0, 0.0, 1.0]}}
        if k < n - 1:
            body["next_joint"] = [0.0, 0.0, 0.1]
        bodies.append(body)
    return {"name": f"chain of {n}", "gravity": [0.0, 0.0, -9.81], "base": {"type": "fixed"}, "bodies": bodies}


def _one_line_refusal(path, needle: str) -> None:
    t0 = time.monotonic()
    with pytest.raises(SceneError) as info:
        load_scene(path)
    assert time.monotonic() - t0 < REFUSAL_SECONDS
    text = str(info.value)
    assert needle in text and "\n" not in text, text


@pytest.mark.slow
def test_a_5000_body_chain_written_by_yaml_safe_dump_loads(tmp_path):
    data = long_chain(5000)
    path = tmp_path / "chain.yaml"
    # what yaml.safe_dump writes (libyaml's emitter when there is one: the same text, faster)
    path.write_text(yaml.dump(data, Dumper=getattr(yaml, "CSafeDumper", yaml.SafeDumper)), encoding="utf-8")
    assert len(path.read_text().splitlines()) > 150_000  # long, and nothing hostile in it
    scene = load_scene(path)
    assert len(scene.bodies) == 5000 and scene.bodies[-1].name == "link4999"
    assert_same(scene, load_scene(data), "file against mapping")


def test_a_billion_laughs_is_refused_quickly_in_one_line(tmp_path):
    # nine levels of nine aliases: 9^9 nodes once expanded; the file is 500 bytes
    lines = ["a0: &a0 [x, x, x, x, x, x, x, x, x]"]
    lines += [f"a{i}: &a{i} [" + ", ".join([f"*a{i - 1}"] * 9) + "]" for i in range(1, 10)]
    path = tmp_path / "laughs.yaml"
    path.write_text("\n".join(lines) + "\n")
    _one_line_refusal(path, "aliases expand to more than")


@pytest.mark.parametrize("text", [
    "name: deep\nbase: {type: fixed}\nbodies: " + "[" * 100_000 + "]" * 100_000 + "\n",  # flow
    "".join(" " * i + "- \n" for i in range(0, 2000, 2)),  # block sequences, one per line
    "name: deep\nbodies: " + "{a: " * 40 + "1" + "}" * 40 + "\n",  # just past the bound
])
def test_a_deeply_nested_file_is_refused_quickly_in_one_line(tmp_path, text):
    path = tmp_path / "deep.yaml"
    path.write_text(text)
    _one_line_refusal(path, "nested deeper than")


def test_aliases_deeper_than_the_bound_once_expanded_are_refused(tmp_path):
    inner = "{a: " * 20 + "1" + "}" * 20
    path = tmp_path / "deep_alias.yaml"
    path.write_text(f"x: &x {inner}\ny: " + "{b: " * 20 + "*x" + "}" * 20 + "\n")
    _one_line_refusal(path, "nested deeper than")


def test_a_character_device_is_refused_without_reading_it():
    if not Path("/dev/zero").exists():
        pytest.skip("no /dev/zero on this system")
    _one_line_refusal("/dev/zero", "is a character device")


def test_a_fifo_is_refused_without_waiting_for_a_writer(tmp_path):
    if not hasattr(os, "mkfifo"):
        pytest.skip("no FIFOs on this system")
    fifo = tmp_path / "scene.yaml"
    os.mkfifo(fifo)
    outcome = []
    done = threading.Event()

    def load():
        try:
            load_scene(fifo)
        except SceneError as exc:
            outcome.append(str(exc))
        done.set()

    threading.Thread(target=load, daemon=True).start()
    finished = done.wait(REFUSAL_SECONDS * 6)
    if not finished:  # let the blocked open return before failing
        os.close(os.open(fifo, os.O_WRONLY | os.O_NONBLOCK))
    assert finished, "load_scene blocked on a FIFO"
    assert outcome and "is a FIFO" in outcome[0] and "\n" not in outcome[0], outcome


def test_a_file_larger_than_the_bound_is_refused_without_reading_it_all(tmp_path):
    from gyro_sim.scene.load import MAX_SCENE_BYTES

    path = tmp_path / "huge.yaml"
    with open(path, "wb") as f:  # sparse: no disk used
        f.truncate(MAX_SCENE_BYTES + 1)
    _one_line_refusal(path, f"larger than {MAX_SCENE_BYTES} bytes")


def test_an_embedded_scene_text_larger_than_the_bound_is_refused():
    from gyro_sim.scene.load import MAX_SCENE_BYTES, parse_yaml

    with pytest.raises(SceneError, match="larger than"):
        parse_yaml("#" * (MAX_SCENE_BYTES + 1), "scene.yaml")


def test_one_problem_is_one_line(tmp_path):
    with pytest.raises(SceneError) as info:
        load_scene(tmp_path / "nowhere.yaml")
    assert "\n" not in str(info.value)


@pytest.mark.parametrize("control", ["high", float("nan")])
def test_a_servos_initial_control_is_a_finite_number(control):

    scene = {"name": "s", "base": {"type": "fixed"},
             "bodies": [{"name": "arm", "joint": {"type": "hinge", "axis": [0.0, 1.0, 0.0],
                                                  "servo": {"gain": 2.0, "bias": [0.0, -2.0, 0.0], "control": control}},
                         "mass": 1.0, "com": [0.0, 0.0, -0.3],
                         "inertia_com": [[0.01, 0, 0], [0, 0.01, 0], [0, 0, 0.005]]}]}
    with pytest.raises(SceneError, match=r"bodies\[0\]\.joint\.servo\.control"):
        load_scene(scene)
    scene["bodies"][0]["joint"]["servo"]["control"] = 0.25
    assert load_scene(scene).bodies[0].joint.servo.control == 0.25
