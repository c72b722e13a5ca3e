"""lie4, the commutator-free Lie group method CF4: :mod:`.driver` (the method), :mod:`.kernels`
(its arithmetic, compiled) and :mod:`.loop` (many steps in one compiled call)."""
