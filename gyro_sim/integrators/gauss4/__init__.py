"""gauss4 and gauss4s, the 2-stage Gauss-Legendre method: :mod:`.driver` (gauss4 on the
package's state), :mod:`.gauss4s` (the same method on the chain's or tree's canonical
equations: symplectic), :mod:`.kernels` (the Newton iterations' arithmetic, compiled) and :mod:`.loop`
(many steps in one compiled call)."""
