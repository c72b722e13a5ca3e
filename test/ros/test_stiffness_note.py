"""The node warns at start when its explicit fixed-step method meets a scene too stiff for
the physics step (and says nothing otherwise)."""
from __future__ import annotations

import yaml

from gyro_sim import Simulator
from gyro_sim.paths import find_scene
from gyro_sim.ros.node import stiffness_note
from gyro_sim.ros.params import validate


def note(scene: str) -> str:
    cfg = validate({"scene": scene, "integrator": "rk4", "physics_rate": 1000.0})
    return stiffness_note(Simulator(cfg.scene, integrator=cfg.integrator, step=cfg.dt), cfg)


def test_no_note_on_the_shipped_hinge_chain():
    assert note("hinge_chain") == ""


def test_a_fast_heavy_top_is_stiff_for_rk4_at_1_khz(tmp_path):
    top = yaml.safe_load(find_scene("heavy_top").read_text())
    top["bodies"][0]["initial"]["euler_rates"][2] = 1e4  # spin, rad/s
    path = tmp_path / "fast_top.yaml"
    path.write_text(yaml.safe_dump(top))
    text = note(str(path))
    assert "stiff for rk4 at physics_rate 1000 Hz" in text and "integrator:=fixed" in text, text
    assert "x40 substeps" in text, text  # what "fixed" would do: 10 rad a step, 0.25 rad a substep


def test_the_default_is_fixed_and_the_start_line_says_what_it_chose(tmp_path):
    from gyro_sim.ros.node import method_choice

    cfg = validate({"scene": "hinge_chain"})
    assert cfg.integrator == "fixed"
    sim = Simulator(cfg.scene, integrator=cfg.integrator, step=cfg.dt)
    assert method_choice(sim, cfg).startswith("rk4: h |lambda| = ")
    assert stiffness_note(sim, cfg) == ""  # "fixed" needs no warning: it substeps, or takes gauss4, where rk4 fails
