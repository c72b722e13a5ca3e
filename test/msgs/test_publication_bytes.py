"""Publication.messages refills messages of fixed layout (io.cdr.Refill): the same bytes as
the builders of io.messages (which test_cdr checks against mcap's generic encoder)."""
from __future__ import annotations

import numpy as np
import pytest

from gyro_sim.snapshot import Snapshot
from gyro_sim.msgs import messages as M


def snapshot(rng, bodies, joints) -> Snapshot:
    n, J = len(bodies), len(joints)
    q = rng.normal(size=(n, 4))
    return Snapshot(time=float(rng.uniform(0, 100)), joint_names=tuple(joints), position=rng.normal(size=J),
                    velocity=rng.normal(size=J), effort=rng.normal(size=J), axis_names=(), axis_moments=np.zeros(0),
                    integrator="rk4", error_estimate=None, body_names=tuple(bodies),
                    body_position=rng.normal(size=(n, 3)), body_quaternion=q / np.linalg.norm(q, axis=1, keepdims=True),
                    wrench_force=rng.normal(size=(n, 3)), wrench_moment=rng.normal(size=(n, 3)))


@pytest.mark.parametrize("seed", range(5))
def test_refilled_messages_are_the_builders_bytes(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 12))
    bodies = ["b" * int(rng.integers(1, 9)) + str(k) for k in range(n)]  # every alignment of the names
    joints = [f"{b}_{a}" for b in bodies for a in ("psi", "theta", "phi")][: int(rng.integers(1, 3 * n + 1))]
    pub = M.Publication(bodies, hardware_id="x")
    for _ in range(3):  # refilled again and again: nothing left over from the last fill
        snap = snapshot(rng, bodies, joints)
        t = int(rng.integers(0, 2**40))
        got = pub.messages(snap, t)
        want = [M.joint_state(snap, t), M.clock(t)]
        want += [M.wrench_stamped(t, b, f, m) for b, f, m in zip(bodies, snap.wrench_force, snap.wrench_moment)]
        want += [M.pose_array(snap, t), M.tf_message(snap, t)]
        assert [g[2] for g in got] == want
        assert [g[0] for g in got][2:2 + n] == list(pub.wrench_topics)


def test_non_finite_values_are_refused_with_their_field():
    rng = np.random.default_rng(0)
    pub = M.Publication(["a", "b"])
    snap = snapshot(rng, ["a", "b"], ["a_psi", "b_psi"])
    snap.wrench_moment[1, 2] = np.nan
    with pytest.raises(M.NonFiniteError, match="wrench b.torque"):
        pub.messages(snap, 0)
    snap = snapshot(rng, ["a", "b"], ["a_psi", "b_psi"])
    snap.velocity[0] = np.inf
    with pytest.raises(M.NonFiniteError, match="joint_states.velocity"):
        pub.messages(snap, 0)
