"""One root for the package's errors: every exception class gyro_sim defines for its users
derives from gyro_sim.errors.GyroSimError (and keeps its standard base)."""
from __future__ import annotations

import importlib
import inspect
import pkgutil
import warnings

import pytest

import gyro_sim
from gyro_sim.errors import GyroSimError

#: classes a user never meets: control flow inside one module
INTERNAL = {"ChunkError", "OutputsClosed"}


def _exception_classes():
    found = {}
    for info in pkgutil.walk_packages(gyro_sim.__path__, "gyro_sim."):
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                mod = importlib.import_module(info.name)
        except ImportError:  # an optional extra (rclpy, rerun, dask) is not installed
            continue
        for name, obj in vars(mod).items():
            if (inspect.isclass(obj) and issubclass(obj, BaseException) and obj.__module__ == mod.__name__
                    and not name.startswith("_") and name not in INTERNAL):
                found[f"{mod.__name__}.{name}"] = obj
    return found


CLASSES = _exception_classes()


def test_the_scan_finds_the_errors_users_catch():
    names = {k.rsplit(".", 1)[1] for k in CLASSES}
    assert {"SceneError", "SimulationError", "IntegrationError", "LogError", "OutputError"} <= names


@pytest.mark.parametrize("name", sorted(CLASSES))
def test_every_error_has_the_root(name):
    cls = CLASSES[name]
    if issubclass(cls, Warning) or not issubclass(cls, Exception):
        return  # warnings, and signals or budgets (BaseException, as KeyboardInterrupt)
    assert issubclass(cls, GyroSimError), name


def test_standard_bases_are_kept():
    from gyro_sim.integrators.base import IntegrationError
    from gyro_sim.scene.load import SceneError
    from gyro_sim.simulator import SimulationError

    assert issubclass(SceneError, ValueError) and issubclass(SimulationError, RuntimeError)
    assert issubclass(IntegrationError, ArithmeticError)
    with pytest.raises(GyroSimError):
        gyro_sim.load_scene({"name": "x", "bodies": []})
