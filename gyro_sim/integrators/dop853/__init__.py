"""dop853, Dormand-Prince 8(5,3): :mod:`.driver` (the adaptive method), :mod:`.kernels` (its
arithmetic, compiled) and :mod:`.loop` (a whole `advance` in one compiled call)."""
