"""The root of every exception gyro_sim raises on purpose.

    try:
        sim = Simulator(load_scene("robot.yaml"))
        sim.advance(10.0)
    except GyroSimError as exc:   # a bad scene, a failed integration, an unreadable log, ...
        print(exc)

Each error keeps the standard base users may already catch: a bad input is also a
``ValueError`` (`SceneError`, `ParameterError`, `OutputError`, `SweepError`,
`NonFiniteError`), a failed run a ``RuntimeError`` (`SimulationError`, `LogError`,
`ClusterError`, `ScreenshotError`), a failed integration an ``ArithmeticError``
(`IntegrationError`). Signals and budgets (`Interrupted`, `OverBudget`) derive from
``BaseException``, as ``KeyboardInterrupt`` does, and are not errors.
"""
from __future__ import annotations


class GyroSimError(Exception):
    """Base class of the package's errors."""
