"""Branch switching at a branch point: the second branch through it, along the
kernel direction of the continuation Jacobian that the followed branch does not
take (Keller, *Numerical solution of bifurcation and nonlinear eigenvalue
problems* (1977); Seydel, *Practical Bifurcation and Stability Analysis*, 3rd ed.
(2010), Sect. 5.6)."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._errors import ValidationError
from .bifurcations import BifurcationPoint
from .continuation import Branch, ContinuationProblem, PseudoArclength, _correct


@jax.jit
def _kernel(jac, tangent):
    # the two right singular vectors of the smallest singular values span the
    # kernel of [G_u, G_p] at a branch point (one of them is the branch's tangent)
    _, _, vt = jnp.linalg.svd(jac)
    basis = vt[-2:]
    c = basis @ tangent
    other = basis.T @ jnp.stack([-c[1], c[0]])
    return other / jnp.linalg.norm(other)


def branch_direction(problem: ContinuationProblem, z: Float[Array, " n+1"],
                     tangent: Float[Array, " n+1"]) -> Float[Array, " n+1"]:
    """The unit direction in (u, p) of the other branch through the branch point z:
    in the two-dimensional kernel of the Jacobian [G_u, G_p] there (the right
    singular vectors of its two smallest singular values), the direction orthogonal
    to the followed branch's `tangent`. Shape (n + 1,). At a symmetry-breaking
    pitchfork of periodic orbits (a Floquet multiplier through +1 without a fold)
    the other branch leaves perpendicular to the followed one (Seydel 2010, Sect.
    5.6)."""
    jac = jax.jacfwd(problem)(jnp.asarray(z, dtype=float))
    return _kernel(jac, jnp.asarray(tangent, dtype=float))


def switch_branch(problem: ContinuationProblem, branch: Branch, point: BifurcationPoint, *,
                  step: float = 0.02, side: int = 1,
                  algorithm: PseudoArclength = PseudoArclength()
                  ) -> tuple[ContinuationProblem, Float[Array, " n+1"]]:
    """A first point of the other branch through a branch point, and the direction
    to follow it: from the branch point z_b step `side * step` along
    `branch_direction`, t, then Newton's method on G = 0 with <t, z - z_b> = side
    * step (Keller's corrector), which keeps it off the followed branch.

    **Arguments:**

    - `problem`: the `ContinuationProblem` of `branch`.
    - `branch`: the followed `Branch`.
    - `point`: a branch point of it (`locate_bifurcations`, kind "branch point").
    - `step`: the arclength from the branch point (> 0).
    - `side`: +1 or -1, which half of the other branch (at a symmetry-breaking
        pitchfork the two halves are symmetric copies of each other).
    - `algorithm`: `PseudoArclength` (Newton's tolerance and budget).

    **Returns:**

    (the problem at the new point, its tangent): pass both to `continuation`
    (`continuation(new, tangent=t)`).

    **Raises:**

    `ValidationError` for a point that is not a branch point, a bad step or side;
    `RuntimeError` if Newton's method does not converge there (try a smaller step).
    """
    if point.kind != "branch point":
        raise ValidationError(f"switch_branch needs a branch point, got a {point.kind}")
    if not step > 0 or side not in (1, -1):
        raise ValidationError(f"switch_branch needs step > 0 and side +1 or -1, got "
                              f"{step!r} and {side!r}")
    ok = np.asarray(branch.converged)
    tangent = branch.tangent[np.nonzero(ok)[0][point.after]]
    direction = side * branch_direction(problem, point.z, tangent)
    z, converged, _, _ = _correct(problem, algorithm, point.z + step * direction, direction)
    if not bool(converged):
        raise RuntimeError(f"switching at the branch point p = {float(point.p):.6g} did "
                           f"not converge: try a smaller step")
    new = eqx.tree_at(lambda pr: pr.u0, problem.with_params(problem.at(z[-1])), z[:-1])
    return new, direction
