"""`gyro-sim bench scaling`: the trees' table (tiny run) and the trees it times."""
import pytest

from gyro_sim.bench import scaling, scenes
from gyro_sim.dynamics import kernel as fast
from gyro_sim.dynamics.model import compile_model
from gyro_sim.scene.load import load_scene


def test_tree_of_links_hangs_the_chain_as_a_tree():
    chain = compile_model(load_scene(scenes.tree_of_links(7, 1)))
    binary = compile_model(load_scene(scenes.tree_of_links(7, 2)))
    hub = compile_model(load_scene(scenes.tree_of_links(7, 7)))
    assert chain.chain and not binary.chain and not hub.chain
    assert list(binary.parent) == [-1, 0, 0, 1, 1, 2, 2]
    assert list(hub.parent) == [-1, 0, 0, 0, 0, 0, 0]
    assert binary.N == hub.N == chain.N == 21


@pytest.mark.skipif(not fast.available(), reason="numba is not installed")
def test_trees_table():
    rows = scaling.trees((3,), min_time=0.005)
    assert len(rows) == 1 and rows[0][0] == 3 and all(t > 0 for t in rows[0][1:])
    text = scaling.trees_table(rows)
    assert text.splitlines()[2].startswith("| 3 | ")
