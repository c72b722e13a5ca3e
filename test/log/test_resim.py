"""Re-simulation of a log: bit for bit with the recorded integrator and commands."""
from __future__ import annotations

import numpy as np
import pytest

from gyro_sim import Simulator, load_scene
from gyro_sim.log.mcap_log import LogWriter, iter_messages, read_info
from gyro_sim.msgs import messages as M
from gyro_sim.log.record import LogRecorder, record_run, run_params
from gyro_sim.log.resim import resimulate

from test.conftest import DURATION, PUBLISH_RATE, SCENE, SCHEDULE, gyro_sim


def test_recorded_run_with_commands_resimulates_bit_for_bit(recorded):
    path, rec = recorded
    # the commands really changed during the run, at step boundaries, as logged
    cmds = [(t, list(m.data)) for _, _, t, m in iter_messages(path, [M.AXIS_MOMENTS])]
    assert [c[1] for c in cmds] == [v for _, v in SCHEDULE]
    assert [c[0] for c in cmds] == [0, 100_000_000, 230_000_000]
    res = resimulate(path)
    assert res.compared == rec.publications == round(DURATION * PUBLISH_RATE) + 1
    assert res.commands == len(SCHEDULE)
    assert res.max_deviation == 0.0, res.report()
    assert res.notes == []


@pytest.mark.slow
def test_cli_reports_deviation_zero(recorded):
    path, _ = recorded
    r = gyro_sim("replay", "--resimulate", path)
    assert r.returncode == 0, r.stderr
    assert "largest deviation: 0.000e+00" in r.stdout and "bit-for-bit" in r.stdout


@pytest.mark.slow
def test_another_integrator_shows_a_deviation_and_says_why(recorded):
    path, _ = recorded
    res = resimulate(path, integrator="rk4")
    assert 0 < res.max_deviation < 1e-2
    assert any("differs from the recorded" in n for n in res.notes)
    r = gyro_sim("replay", "--resimulate", path, "--integrator", "rk4")
    assert r.returncode == 1 and "differs from the recorded" in r.stdout


def test_a_one_ulp_change_in_the_log_is_found(tmp_path):
    """The comparison is exact: a joint state off by one ulp at one time is reported there."""
    scene = load_scene(SCENE)
    sim = Simulator(scene)
    real = sim.snapshot
    bad_time = 0.06

    def snapshot(**kw):  # what the recorder logs: the snapshot's joint states
        snap = real(**kw)
        if abs(sim.time - bad_time) < 1e-9:
            snap.position[4] = float(np.nextafter(snap.position[4], np.inf))
        return snap

    sim.snapshot = snapshot
    path = tmp_path / "ulp.mcap"
    record_run(sim, path, duration=0.1, chunk=0.01, publish_rate=100, schedule=SCHEDULE[:2])
    res = resimulate(path)
    assert res.max_deviation > 0
    assert res.worst[0] == pytest.approx(bad_time) and res.worst[2] == "position"


def test_resets_and_commands_of_a_live_style_log_resimulate(tmp_path):
    """The recorder contract the node follows: fixed advance_dt, commands and a reset event."""
    scene = load_scene(SCENE)
    sim = Simulator(scene, integrator="lie4", step=1e-3)
    dt = 0.004
    path = tmp_path / "live.mcap"
    with LogWriter(path, scene=scene, params=run_params(sim, advance_dt=dt, publish_rate=125, source="test")) as w:
        r = LogRecorder(w, sim)
        for i in range(60):
            if i % 2 == 0:
                r.publish()
            if i in (5, 33):
                r.command([0.003, -0.01 * i, 0.02])
                sim.set_axis_moments([0.003, -0.01 * i, 0.02])
            if i == 26:  # right after a publication at the same log time
                r.reset()
                r.publish()
            sim.advance(dt)
        r.publish()
    res = resimulate(path)
    assert res.resets == 1 and res.commands == 2
    assert res.compared == 32 and res.off_boundary == 0
    assert res.max_deviation == 0.0, res.report()


def test_embedded_parameters_make_the_log_self_contained(recorded):
    path, _ = recorded
    p = read_info(path).params
    for key in ("integrator", "rtol", "atol", "step", "advance_dt", "publish_rate", "axis_names",
                "command_schedule", "gyro_sim_version", "numpy", "machine"):
        assert key in p, key
    assert p["advance_dt"] == 0.005 and p["publish_rate"] == PUBLISH_RATE
    assert p["command_schedule"] == [[t, v] for t, v in SCHEDULE]


@pytest.mark.slow
def test_run_records_zero_commands_and_resimulates(tmp_path):
    path = tmp_path / "cli.mcap"
    r = gyro_sim("run", "--scene", "double_gyro_plus", "--duration", "0.2", "--record", path, "--publish-rate", "50")
    assert r.returncode == 0, r.stderr
    assert "gyro-sim view" in r.stdout and "kB per simulated second" in r.stdout
    info = read_info(path)
    assert info.params["command_schedule"] == [[0.0, []]]  # no actuated axes in this scene
    assert info.message_count > 0
    res = resimulate(path)
    assert res.compared == 11 and res.max_deviation == 0.0


def _switching_log(path, switch_at: int, event: str | None = None, event_at: int | None = None) -> None:
    """A node-style log of hinge_chain under "fixed" at 1 kHz that starts on numpy ("dynamics":
    numpy) and switches to numba after `switch_at` steps, said by the node's event (or `event`)
    at that step boundary (or at `event_at`'s: a log that misplaces it)."""
    from gyro_sim.log.resim import DYNAMICS_EVENT

    scene = load_scene(SCENE)
    sim = Simulator(scene, integrator="fixed", step=1e-3, backend="numpy")
    dt = 1e-3
    params = run_params(sim, advance_dt=dt, publish_rate=100, source="test", dynamics=sim.backend)
    with LogWriter(path, scene=scene, params=params) as w:
        r = LogRecorder(w, sim)
        for i in range(120):
            if i % 10 == 0:
                r.publish()
            if i == (switch_at if event_at is None else event_at):
                r.event(event or f"{DYNAMICS_EVENT}numba from here (numpy until now, while its kernels compiled)")
            if i == switch_at:
                sim.switch_backend("numba")
            if i in (0, 50):
                r.command([0.002, 0.03 - 0.001 * i, -0.02])
                sim.set_axis_moments([0.002, 0.03 - 0.001 * i, -0.02])
            sim.advance(dt)
        r.publish()


def test_a_switch_of_backend_in_the_log_is_repeated_at_its_step(tmp_path):
    """The node's start on numpy, then on the compiled kernels (gyro_sim.warmup.start_deferred):
    re-simulation starts on the recorded backend and switches at the event's step boundary:
    bit for bit. A log whose event says one step later than the run switched is not
    reproduced (the two backends differ in rounding): the event is what decides."""
    path = tmp_path / "switch.mcap"
    _switching_log(path, 43)
    res = resimulate(path)
    assert res.switches == 1 and res.compared == 13
    assert res.max_deviation == 0.0, res.report()
    assert "switched 1 time as recorded" in res.report()
    misplaced = tmp_path / "misplaced.mcap"
    _switching_log(misplaced, 43, event_at=44)
    assert resimulate(misplaced).max_deviation > 0.0


def test_a_switch_to_an_unknown_backend_is_refused(tmp_path):
    from gyro_sim.log.mcap_log import LogError

    path = tmp_path / "bad.mcap"
    _switching_log(path, 20, event="dynamics: cuda from here")
    with pytest.raises(LogError, match="unknown backend 'cuda'"):
        resimulate(path)
