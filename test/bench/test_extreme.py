"""The stiff and extreme scenes (gyro_sim.bench.extreme): they load, they are what they
claim to be, and the shipped files are what the builders write."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from gyro_sim.bench import extreme as ex
from gyro_sim.bench.scenes import spherical_chain
from gyro_sim.dynamics.system import make_system
from gyro_sim.dynamics.model import compile_model, initial_state
from gyro_sim.scene.load import load_scene

CONFIG = Path(__file__).resolve().parents[2] / "config"

BUILDERS = {
    "fast_rotor": lambda: ex.fast_rotor(1e4),
    "fast_rotor_precession": lambda: ex.fast_rotor_precession(1e4),
    "light_tip": lambda: ex.mass_ratio_chain(1e-6),
    "heavy_tip": lambda: ex.mass_ratio_chain(1e6),
    "kapitza_below": lambda: ex.kapitza(0.5),
    "kapitza_above": lambda: ex.kapitza(3.77),
    "nutating_top": ex.nutating_top,
    "looping_top": ex.looping_top,
    "near_spherical": ex.near_spherical_top,
    "thin_rod": ex.thin_rod_top,
    "flat_disc": ex.flat_disc_top,
    "abrupt": lambda: ex.abrupt_commands()[0],
}


@pytest.mark.parametrize("name", BUILDERS)
def test_builders_load(name):
    scene = load_scene(BUILDERS[name]())
    assert scene.bodies


@pytest.mark.parametrize("fname", ex.SHIPPED)
def test_shipped_files_regenerate(fname):
    assert (CONFIG / fname).read_text(encoding="utf-8") == ex.shipped_yaml(fname), \
        f"config/{fname} is stale: run python -m gyro_sim.bench.extreme config"


def _jacobian_eigenvalues(sd):
    model = compile_model(load_scene(sd))
    system = make_system(model, "numpy")
    y = initial_state(model)
    f0 = system.rhs(0.0, y).copy()
    J = np.empty((y.size, y.size))
    for j in range(y.size):
        d = 1e-7 * max(1.0, abs(y[j]))
        yj = y.copy()
        yj[j] += d
        J[:, j] = (system.rhs(0.0, yj) - f0) / d
    return np.linalg.eigvals(J)


def test_fast_rotor_frequency_ratio():
    """Nutation: the largest eigenvalue pair of the linearisation; >= 1e4 x precession."""
    sd = ex.fast_rotor_precession(1e4)
    w_n = np.max(np.abs(_jacobian_eigenvalues(sd).imag))
    kappa = abs(sd["bodies"][0]["initial"]["euler_rates"][0])  # the slow precession rate
    assert w_n / kappa >= 1e4 * 0.99
    assert w_n == pytest.approx(ex.fast_rotor_frequencies(ex.fast_rotor_spin(1e4))[0], rel=0.01)
    # and the carrier itself does not spin: the slow precession branch
    assert abs(sd["bodies"][0]["initial"]["euler_rates"][2]) < 1e-5


def test_mass_ratios():
    for ratio in (1e-6, 1e6):
        bodies = ex.mass_ratio_chain(ratio)["bodies"]
        assert bodies[2]["mass"] / bodies[1]["mass"] == pytest.approx(ratio)


def test_kapitza_margin():
    f = ex.kapitza_threshold_frequency()
    assert ex.kapitza_margin(f) == pytest.approx(1.0)
    shipped = ex.load_dict("vibrating_base")["base"]["motion"]["frequency"]
    assert ex.kapitza_margin(shipped) == pytest.approx(3.77, abs=0.01)  # as its comment says
    assert ex.kapitza(0.5)["base"]["motion"]["frequency"] == pytest.approx(f * math.sqrt(0.5))


def test_abrupt_moments_are_1e3_gravity_torques():
    scene, moments = ex.abrupt_commands()
    assert len(moments) == 3
    # arm4's hinge: its own gravity torque m g c at most (horizontal lever)
    assert abs(moments[2]) == pytest.approx(1e3 * 0.2 * 9.81 * 0.06)


def test_long_chains_build():
    for n in (100, 200):
        assert len(spherical_chain(n)["bodies"]) == n
