"""radau, Radau IIA with 3 stages (stiff): :mod:`.driver` (the adaptive method), :mod:`.kernels`
(its arithmetic and LU, compiled) and :mod:`.loop` (a whole `advance` in one compiled call)."""
