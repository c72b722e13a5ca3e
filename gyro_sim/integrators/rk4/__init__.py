"""rk4, the classical Runge-Kutta method: :mod:`.driver` (the method), :mod:`.kernels` (the
arithmetic of an explicit Runge-Kutta step, compiled) and :mod:`.loop` (many steps in one
compiled call, and the numba cache helpers the other compiled loops use)."""
