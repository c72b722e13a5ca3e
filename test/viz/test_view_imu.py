"""An IMU's readings in the log view: its own plots, next to the joint it rides on."""
from __future__ import annotations

import numpy as np
import pytest

from test.conftest import gyro_sim
from test.viz.test_live import chunks, column

pytest.importorskip("rerun")


@pytest.mark.slow
def test_the_imu_of_a_pendulum_is_plotted_and_reads_the_hinge_rate(tmp_path):
    log, rrd = tmp_path / "imu.mcap", tmp_path / "imu.rrd"
    r = gyro_sim("run", "--scene", "imu_pendulum", "--duration", 3, "--record", log, timeout=300)
    assert r.returncode == 0, r.stderr
    r = gyro_sim("view", log, "--save", rrd)
    assert r.returncode == 0, r.stderr
    assert "plots/imu/tip_imu/gyro" in r.stdout  # a view of its own in the layout
    got = chunks(rrd)
    gyro = np.array(column(got["/plots/imu/tip_imu/gyro"], "Scalars:scalars"), float)
    accel = np.array(column(got["/plots/imu/tip_imu/accel"], "Scalars:scalars"), float)
    names = column(got["/plots/imu/tip_imu/gyro"], "SeriesLines:names")
    assert names[0] == ["tip_imu wx", "tip_imu wy", "tip_imu wz"]
    assert gyro.shape[1] == 3 and accel.shape[1] == 3 and len(gyro) > 100
    # the pendulum swings about the world's x axis, which is its IMU's x axis: the gyro's x
    # reading follows the hinge's rate (up to the IMU's noise)
    from gyro_sim.log.mcap_log import iter_messages

    hinge_rate = np.array([m.velocity[list(m.name).index("pendulum")]
                           for _, _, _, m in iter_messages(log, ["/joint_states"])])
    n = min(len(hinge_rate), len(gyro))
    assert np.corrcoef(hinge_rate[:n], gyro[:n, 0])[0, 1] > 0.9
    assert np.std(hinge_rate) > 0.01  # it does swing
