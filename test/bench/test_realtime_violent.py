"""The violent step of `gyro-sim bench realtime --violent`, counted: what "fixed" spends per
simulated second after it stays within the real-time budget, and the energy it put in is
accounted for."""
import numpy as np
import pytest

from gyro_sim.bench import realtime
from gyro_sim.integrators import fixed


@pytest.fixture(scope="module")
def counts():
    return realtime.violent_counts()


def test_after_the_violent_step_fixed_spends_within_its_budget(counts):
    """The budget: EVAL_BUDGET evaluations a physics step, from a measured cost of 0.6-1.1 us an
    evaluation of this chain (less than half of each 1 ms period: docs/integrators.md)."""
    assert counts["finite"]
    assert counts["evaluations_per_s_after"] <= fixed.EVAL_BUDGET * realtime.PHYSICS_RATE
    # during the push, the credit's burst once (a retake, the rescue) and one call beyond it at most
    push_steps = counts["push_s"] * realtime.PHYSICS_RATE
    spent = counts["evaluations_per_s_push"] * counts["push_s"]
    assert spent <= fixed.EVAL_BUDGET * push_steps + fixed.BURST_STEPS * fixed.EVAL_BUDGET \
        + counts["most_evaluations_in_a_call"]
    # every substep of at most MAX_SUBSTEPS a physics step: nothing is left unresolved silently
    assert counts["substeps_per_s_after"] <= fixed.MAX_SUBSTEPS * realtime.PHYSICS_RATE


def test_the_violent_step_puts_in_its_energy_and_keeps_the_balance(counts):
    """The energy put in is the work of the held moments (1e10 J and more, from 13 J at rest):
    E - E0 - W stays below 1e-2 of E (the drift over budget is reported, not hidden), and the
    drift reported over budget is finite."""
    assert counts["energy_put_in_J"] > 1e9
    assert abs(counts["energy_balance_relative"]) < 1e-2
    assert np.isfinite(counts["over_budget_energy_error"])


def test_the_push_ends_the_same_way_every_run(counts):
    """Every decision depends on the simulated states only: a second run gives the same counts."""
    again = realtime.violent_counts()
    assert again == counts
