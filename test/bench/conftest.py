"""Both reports run once per test session in quick mode, through the command line, into a
temporary directory; the tests read what they wrote (Markdown, JSON, PNG)."""
from __future__ import annotations

import json

import pytest

from gyro_sim.cli import main


@pytest.fixture(scope="session")
def accuracy_out(tmp_path_factory):
    out = tmp_path_factory.mktemp("accuracy")
    assert main(["bench", "accuracy", "--quick", "--out", str(out)]) == 0
    return out, json.loads((out / "accuracy.json").read_text()), (out / "accuracy.md").read_text()


@pytest.fixture(scope="session")
def stability_out(tmp_path_factory):
    out = tmp_path_factory.mktemp("stability")
    assert main(["bench", "stability", "--quick", "--out", str(out)]) == 0
    return out, json.loads((out / "stability.json").read_text()), (out / "stability.md").read_text()
