"""Logs open in rerun: `rerun mcap convert` and `gyro-sim view --save`, inspected."""
from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from gyro_sim import load_scene
from gyro_sim.msgs import messages as M
from gyro_sim.log.mcap_log import iter_messages

from test.conftest import SCENE, gyro_sim

rr = pytest.importorskip("rerun")
_BESIDE = Path(sys.executable).with_name("rerun")  # the venv's own binary, else the one on PATH
RERUN = str(_BESIDE) if _BESIDE.is_file() else shutil.which("rerun")
pytestmark = pytest.mark.skipif(RERUN is None, reason="the rerun binary (rerun-sdk) is not installed")


def chunks(rrd):
    """entity path -> list of record batches (temporal chunks) of an .rrd file."""
    from rerun.chunk import RrdReader

    out: dict[str, list] = {}
    for c in RrdReader(rrd).stream():
        out.setdefault(c.entity_path, []).append(c.to_record_batch())
    return out


def column(batches, name):
    return [v for b in batches if name in b.schema.names for v in b.column(name).to_pylist()]


def test_rerun_mcap_convert_holds_joint_scalars_and_body_transforms(recorded, tmp_path):
    path, rec = recorded
    rrd = tmp_path / "log.rrd"
    r = subprocess.run([RERUN, "mcap", "convert", str(path), "-o", str(rrd)], capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 0, r.stderr
    got = chunks(rrd)
    bodies = [b.name for b in load_scene(SCENE).bodies]
    logged = [(t, m) for topic, _, t, m in iter_messages(path, [M.JOINT_STATES])]
    assert len(logged) == rec.publications
    # joint states: one Scalars series per field, named after the joints, values as logged
    for field in ("position", "velocity", "effort"):
        batches = got[f"/joint_states/{field}"]
        names = column(batches, "SeriesLines:names")
        values = column(batches, "Scalars:scalars")
        assert len(values) == len(logged)
        assert names[0] == list(logged[0][1].name)
        assert np.array_equal(np.array(values), np.array([list(getattr(m, field)) for _, m in logged]))
    # /tf: a Transform3D world -> body for every body at every publication
    tf = got["/tf"]
    child, parent = column(tf, "Transform3D:child_frame"), column(tf, "Transform3D:parent_frame")
    trans = np.array([v[0] for v in column(tf, "Transform3D:translation")])
    assert sorted({c[0] for c in child}) == sorted(bodies)
    assert {p[0] for p in parent} == {"world"}
    assert len(child) == len(bodies) * rec.publications
    last = [m for _, _, _, m in iter_messages(path, [M.TF])][-1]
    exp = np.array([[tr.transform.translation.x, tr.transform.translation.y, tr.transform.translation.z]
                    for tr in last.transforms])
    assert np.allclose(trans[-len(bodies):], exp, atol=1e-6)  # rerun stores float32
    # the URDF on /robot_description: each body's shape in its own frame, which /tf moves
    for b in bodies:
        visual = got[f"/gyro_sim/visual_geometries/{b}/visual_0"]
        assert column(visual, "CoordinateFrame:frame") == [[b]]
        assert column(visual, "Cylinders3D:lengths")
    quats = np.array([v[0] for v in column(tf, "Transform3D:quaternion")])
    q = [tr.transform.rotation for tr in last.transforms]
    assert np.allclose(quats[-len(bodies):], [[r.x, r.y, r.z, r.w] for r in q], atol=1e-6)


@pytest.mark.slow
def test_view_save_writes_a_verified_rrd_with_the_chain_and_plots(recorded, tmp_path):
    path, _ = recorded
    rrd = tmp_path / "view.rrd"
    r = gyro_sim("view", path, "--save", rrd)
    assert r.returncode == 0, r.stderr
    v = subprocess.run([RERUN, "rrd", "verify", str(rrd)], capture_output=True, text=True, timeout=120)
    assert v.returncode == 0, v.stdout + v.stderr
    got = chunks(rrd)
    scene = load_scene(SCENE)
    expected = {"/world/links", "/world/base", "/world/gravity", "/world/angular_momentum",
                "/plots/drift/vertical_momentum", "/plots/balance/energy_balance"}
    for b in scene.bodies:
        expected |= {f"/world/{b.name}", f"/world/{b.name}/body", f"/world/{b.name}/wrench/force",
                     f"/world/{b.name}/wrench/moment"}
        expected.add(f"/plots/{'hinge' if b.joint.type == 'hinge' else 'euler'}/{b.name}")
        for rot in b.rotors:
            expected |= {f"/world/{b.name}/{rot.name}/spin", f"/world/{b.name}/{rot.name}/spin/disc",
                         f"/plots/rotor_rate/{rot.name}"}
    expected |= {f"/plots/axis_moments/{a}" for a in ("wheel2", "arm3", "arm4")}
    assert expected <= set(got), sorted(expected - set(got))
    # the log is commanded: the energy is not conserved, its drift is not shown as if it were
    assert "/plots/drift/energy" not in got
    # what they hold: moving body frames, spinning rotor, arrows, plotted series
    assert len(column(got["/world/arm1"], "Transform3D:translation")) > 10
    assert len(column(got["/world/arm2/wheel2/spin"], "Transform3D:quaternion")) > 10
    assert column(got["/world/arm1/body"], "Capsules3D:lengths")
    assert column(got["/world/arm3/wrench/force"], "Arrows3D:vectors")
    assert len(column(got["/world/links"], "LineStrips3D:strips")) > 10
    moments = np.array(column(got["/plots/axis_moments/arm3"], "Scalars:scalars")).ravel()
    assert set(np.round(moments, 6)) >= {0.0, 0.02, -0.01}  # the commanded steps
    euler = column(got["/plots/euler/arm1"], "Scalars:scalars")
    assert len(euler[0]) == 3
    # the blueprint: a 3D view and time-series views
    from rerun.chunk import RrdReader

    assert RrdReader(rrd).blueprints(), "no blueprint in the recording"
