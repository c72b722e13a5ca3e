"""Linear models of a chain about a state: `linearize` (docs/linearization.md).

    from gyro_sim.linear import linearize
    lin = linearize(model, t, y, spins, moments)      # or Simulator.linearize()
    lin.A, lin.B, lin.f0, lin.state_names, lin.input_names, lin.is_equilibrium
    lin.discrete(0.01, "zoh")                         # Ad, Bd of one step

`gyro-sim linearize SCENE` prints the eigenvalues and the verdict (gyro_sim.linear.commands).
"""
from gyro_sim.linear.linearize import Linearization, linearize

__all__ = ["Linearization", "linearize"]
