"""The sweep's eigenvalue measure: the sleeping-top map from linearisations (no simulation)
against Maievski's criterion, cell for cell, and each unstable point's growth rate against the
closed form sqrt(4 B m g c - (A p)^2) / (2 B) (docs/theory.md section 9)."""
from __future__ import annotations

import math

import pytest

pytest.importorskip("pyarrow")

from gyro_sim.sweep import execute, results
from gyro_sim.sweep.commands import find_sweep
from gyro_sim.sweep.spec import SweepError, load_sweep

KEY_C, KEY_P = "bodies[0].com[2]", "bodies[0].initial.angular_velocity[2]"


def test_sleeping_top_map_from_eigenvalues_matches_maievski_cell_for_cell(tmp_path):
    sweep = load_sweep(find_sweep("sleeping_top_linear"), quick=True)
    execute.run(sweep, tmp_path, workers=0)
    rows = results.read_parts(tmp_path)
    assert len(rows) == len(sweep.points) == 190 and all(r["ok"] and r["t_reached"] == 0.0 for r in rows)
    done = results.finish(sweep, tmp_path, rows, {})
    assert done["check"]["disagree"] == 0, done["check"]
    assert {r["verdict.stays_up"] for r in rows} == {True, False}
    assert "- run: none, a linearisation at each point's initial state" in (tmp_path / results.SUMMARY).read_text()
    A, B, m, g = 0.004, 0.015, 1.0, 9.81  # config/heavy_top.yaml's top
    unstable = 0
    for r in rows:
        c, p = r[KEY_C], r[KEY_P]
        disc = 4 * B * m * g * c - (A * p) ** 2
        if disc > 0:
            unstable += 1
            want = math.sqrt(disc) / (2 * B)
            assert abs(r["max_real_eig"] - want) <= 1e-9 * want, (c, p, r["max_real_eig"], want)
        else:
            assert abs(r["max_real_eig"]) <= r["eig_tolerance"]
    assert unstable > 10


def test_an_eigenvalue_verdict_needs_the_measure(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text(find_sweep("sleeping_top_linear").read_text().replace("measures: [eigenvalues]",
                                                                       "measures: [max_tilt]"))
    with pytest.raises(SweepError, match="needs 'eigenvalues'"):
        load_sweep(bad)
