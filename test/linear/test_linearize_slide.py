"""The linear model of a chain with a slide (docs/theory.md section 12): the cart-pole upright,
its eigenvalues against the roots of det(K - s^2 M) written by hand, with and without an
armature and a spring on the cart's slide; the complex step against central differences."""
from __future__ import annotations

import math

import numpy as np
import pytest

from gyro_sim import Simulator
from test.dynamics.test_slide import IC, G, L, M, cart_pole, m
from test.linear.test_linearize import _close_sets


@pytest.mark.parametrize("armature, stiffness", [(0.0, 0.0), (0.3, 5.0)])
def test_upright_cart_pole_has_the_closed_form_eigenvalues(armature, stiffness):
    """About x = th = 0 at rest: M0 q'' = K q with M0 = [[M + m + a, m l], [m l, J]] (J = m l^2 +
    Ic) and K = diag(-k, m g l); s^2 solves (Mt J - m^2 l^2) s^4 + (k J - Mt m g l) s^2 - k m g l
    = 0, Mt = M + m + a. Without the spring: s = +-sqrt(Mt m g l / (Mt J - m^2 l^2)) and a double
    zero (the cart's position and velocity)."""
    joint = {"armature": armature, "spring": {"stiffness": stiffness}} if stiffness else {}
    lin = Simulator(cart_pole(**joint), backend="numpy").linearize()
    Mt, J, mgl = M + m + armature, m * L * L + IC, m * G * L
    det = Mt * J - (m * L) ** 2
    if stiffness:
        b = stiffness * J - Mt * mgl
        roots = [(-b + sgn * math.sqrt(b * b + 4.0 * det * stiffness * mgl)) / (2.0 * det) for sgn in (1, -1)]
        want = [s for r in roots for s in ((math.sqrt(r), -math.sqrt(r)) if r > 0 else (1j * math.sqrt(-r),
                                                                                          -1j * math.sqrt(-r)))]
    else:
        r = math.sqrt(Mt * mgl / det)
        want = [r, -r, 0.0, 0.0]
    assert lin.state_names[:2] == ("cart", "pole") and lin.output_names[0] == "cart.position"
    _close_sets(lin.eigenvalues(), want)


def test_complex_step_agrees_with_central_differences_on_slides():
    from test.dynamics.test_slide import closed_chain

    sim = Simulator(closed_chain(), backend="numpy")
    sim.advance(0.05)
    sim.set_axis_moments(0.01 * np.arange(1, len(sim.axis_names) + 1))
    exact, fd = sim.linearize(), sim.linearize(method="fd")
    for name in "AB":
        a, b = getattr(exact, name), getattr(fd, name)
        assert np.max(np.abs(a - b)) <= 1e-6 * max(1.0, np.max(np.abs(a))), name
