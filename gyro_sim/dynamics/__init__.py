"""The chain's dynamics: the paper's equations, a numpy reference and the compiled kernels.

- :mod:`.model`: a scene compiled into the arrays the dynamics reads (immutable)
- :mod:`.reference`: eqs (34)-(54) as a world-frame Newton-Euler recursion in numpy (the oracle)
- :mod:`.kernel`: the same equations as an O(n) articulated-body recursion compiled with numba
- :mod:`.entry`: one compiled evaluation called from Python at a small fixed cost
- :mod:`.outputs`: what one publication shows (joint states, poses, wrenches, invariants), compiled
- :mod:`.canonical`, :mod:`.canonical_kernel`: the chain's (or tree's) canonical (Hamiltonian) form, for gauss4s
- :mod:`.rotations`: quaternions, rotation matrices and the paper's Euler angles
- :mod:`.invariants`: energy, angular momentum and the other monitors of the motion
- :mod:`.system`: the chain as an ODE system for the integrators, and the choice of backend
"""
