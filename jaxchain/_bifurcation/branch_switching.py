"""Branch switching at a branch point: the second branch through it, along the
kernel direction of the continuation Jacobian that the followed branch does not
take (Keller, *Numerical solution of bifurcation and nonlinear eigenvalue
problems* (1977); Seydel, *Practical Bifurcation and Stability Analysis*, 3rd ed.
(2010), Sect. 5.6), or, where the kernel has more dimensions than that (a
symmetric ring), by deflation from the followed branch's orbits beside it, or along
the lines of the kernel that the ring's symmetries fix (the equivariant branching
lemma)."""

import itertools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._errors import ValidationError
from .bifurcations import BifurcationPoint
from .continuation import Branch, ContinuationProblem, PseudoArclength, _correct
from .deflation import distinct_orbits


def branch_direction(problem: ContinuationProblem, z: Float[Array, " n+1"],
                     tangent: Float[Array, " n+1"]) -> Float[Array, " n+1"]:
    """The unit direction in (u, p) of the other branch through the branch point z:
    in the two-dimensional kernel of the Jacobian [G_u, G_p] there (the right
    singular vectors of its two smallest singular values), the direction orthogonal
    to the followed branch's `tangent` (`critical_directions` with one direction).
    Shape (n + 1,). At a symmetry-breaking pitchfork of periodic orbits (a Floquet
    multiplier through +1 without a fold) the other branch leaves perpendicular to
    the followed one (Seydel 2010, Sect. 5.6)."""
    return jnp.asarray(critical_directions(problem, z, tangent, count=1)[0])


def switch_branch(problem: ContinuationProblem, branch: Branch, point: BifurcationPoint, *,
                  step: float = 0.02, side: int = 1,
                  algorithm: PseudoArclength = PseudoArclength(), direction=None
                  ) -> tuple[ContinuationProblem, Float[Array, " n+1"]]:
    """A first point of the other branch through a branch point, and the direction
    to follow it: from the branch point z_b step `side * step` along
    `branch_direction` (or `direction`), t, then Newton's method on G = 0 with
    <t, z - z_b> = side * step (Keller's corrector), which keeps it off the
    followed branch.

    **Arguments:**

    - `problem`: the `ContinuationProblem` of `branch`.
    - `branch`: the followed `Branch`.
    - `point`: a branch point of it (`locate_bifurcations`, kind "branch point").
    - `step`: the arclength from the branch point (> 0).
    - `side`: +1 or -1, which half of the other branch (at a symmetry-breaking
        pitchfork the two halves are symmetric copies of each other).
    - `algorithm`: `PseudoArclength` (Newton's tolerance and budget).
    - `direction`: the unit direction in (u, p) to step along, shape (n + 1,),
        instead of `branch_direction`: one of `symmetric_directions` where the
        kernel has more than one critical direction.

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
    if direction is None:
        tangent = branch.tangent[np.nonzero(ok)[0][point.after]]
        direction = branch_direction(problem, point.z, tangent)
    direction = side * jnp.asarray(direction, dtype=float)
    z, converged, _, _ = _correct(problem, algorithm, point.z + step * direction, direction)
    if not bool(converged):
        raise RuntimeError(f"switching at the branch point p = {float(point.p):.6g} did "
                           f"not converge: try a smaller step")
    new = eqx.tree_at(lambda pr: pr.u0, problem.with_params(problem.at(z[-1])), z[:-1])
    return new, direction


#: The critical singular values of [G_u, G_p] at a branch point are those below the
#: largest gap among its `_CRITICAL` smallest ones.
_CRITICAL = 4


def critical_directions(problem: ContinuationProblem, z: Float[Array, " n+1"],
                        tangent: Float[Array, " n+1"], *, count: int | None = None
                        ) -> Float[np.ndarray, "k n+1"]:
    """An orthonormal basis of the kernel of the continuation Jacobian [G_u, G_p] at
    the branch point z, less the followed branch's `tangent`: the directions in
    which other branches can leave. The kernel is spanned by the right singular
    vectors of the critical singular values (those below the largest ratio between
    neighbours among the four smallest) and the one that an n x (n + 1) matrix
    always has. At a generic branch point k = 1; where the chain's symmetry makes a
    Floquet multiplier +1 double (a two-dimensional irreducible representation of
    the ring's dihedral group), k = 2 (Golubitsky, Stewart and Schaeffer,
    *Singularities and Groups in Bifurcation Theory* II (1988), ch. XIII); `count`
    sets k instead. Each direction's largest component is positive (the sign of a
    singular vector is otherwise arbitrary). Shape (k, n + 1)."""
    jac = np.asarray(jax.jacfwd(problem)(jnp.asarray(z, dtype=float)))
    _, s, vt = np.linalg.svd(jac)
    # the smallest first, each at least the rounding of the largest: below it two
    # singular values are alike (an exact zero and 1e-17 make no gap)
    small = np.maximum(s[::-1][:_CRITICAL + 1], s[0] * max(jac.shape) * np.finfo(float).eps)
    k = count or 1 + int(np.argmax(small[1:] / small[:-1]))
    kernel = vt[-(k + 1):]  # k critical directions and the always-present one
    t = np.asarray(tangent, dtype=float) / np.linalg.norm(tangent)
    rest = kernel - np.outer(kernel @ t, t)
    basis, _, _ = np.linalg.svd(rest.T, full_matrices=False)
    directions = basis[:, :k].T
    largest = directions[np.arange(k), np.argmax(np.abs(directions), axis=1)]
    return directions * np.sign(largest)[:, None]


def symmetric_directions(problem: ContinuationProblem, z: Float[Array, " n+1"],
                         tangent: Float[Array, " n+1"], actions, *, tol: float = 1e-2
                         ) -> Float[np.ndarray, "m n+1"]:
    """The lines of the critical plane at the branch point z that a symmetry fixes,
    one of each kind: where the kernel of [G_u, G_p] has several critical
    directions (`critical_directions`: a Floquet multiplier +1 of a two-dimensional
    irreducible representation of the ring's dihedral group), branches leave along
    the lines of it fixed by a subgroup of the symmetries of the orbit at z, the
    axes of the equivariant branching lemma (Golubitsky, Stewart and Schaeffer,
    *Singularities and Groups in Bifurcation Theory* II (1988), ch. XIII, Thm. 3.3;
    on the dihedral groups ch. XVIII); off them a step of `switch_branch` lands
    nowhere near a branch. For each symmetry of `actions`, the critical directions
    c it fixes (c[a] = c) are the null space of the matrix of c[a] - c over the
    plane; a one-dimensional null space is an axis. Axes mapped onto each other
    by a symmetry lead to copies of one branch: the first of each is kept.

    **Arguments:**

    - `problem`, `z`, `tangent`: as for `critical_directions` (z a branch point).
    - `actions`: the symmetries of the orbit at z as permutations of the
        components of z, shape (s, n + 1) (on the shooting unknowns (x, x', T, p)
        of a chain: each permutation of the oscillators applied to x and to x',
        T and p fixed), the identity included or not.
    - `tol`: a singular value of c[a] - c below `tol` (its largest is 2) counts
        as zero. The critical plane is known as well as the branch point is
        located: at the whole ring of 20's (exact model, v_d 1.7404) the lines
        that reflections fix give 3e-6 to 5e-3, the other symmetries 0.36 and
        more.

    **Returns:**

    The axes, unit vectors with their largest component positive, shape (m,
    n + 1); at a generic branch point (one critical direction), that direction
    (m = 1). Empty (m = 0) where no symmetry fixes a line of the plane.

    **Raises:**

    `ValidationError` for actions that are not permutations of z's components.
    """
    actions = np.atleast_2d(np.asarray(actions, dtype=int))
    n = np.asarray(z).size
    if actions.shape[1] != n or np.any(np.sort(actions, axis=1) != np.arange(n)):
        raise ValidationError(f"symmetric_directions needs permutations of the {n} "
                              f"components of z, got shape {actions.shape}")
    plane = critical_directions(problem, z, tangent)
    if len(plane) == 1:
        return plane
    axes = []
    for a in actions:
        _, s, vt = np.linalg.svd((plane[:, a] - plane).T)
        if not (s[-1] < tol and (len(s) < 2 or s[-2] >= tol)):
            continue  # the symmetry fixes no line of the plane, or all of it
        axis = vt[-1] @ plane
        axis = axis / np.linalg.norm(axis) * np.sign(axis[np.argmax(np.abs(axis))])
        if not any(np.max(np.abs(axis[actions] @ known)) > 1.0 - tol for known in axes):
            axes.append(axis)
    return np.asarray(axes).reshape(-1, n)


def switch_by_deflation(problem: ContinuationProblem, branch: Branch, point: BifurcationPoint,
                        *, offset: float = 0.01, amplitudes=(0.02, 0.1), count: int = 2,
                        algorithm: PseudoArclength = PseudoArclength()
                        ) -> list[tuple[ContinuationProblem, Float[Array, " n+1"]]]:
    """Orbits of the other branches through a branch point, found by deflation
    where Keller's step (`switch_branch`) fails: at p = p_b +- `offset`, the followed
    branch's orbit there (the corrector with p held) is deflated with its symmetric
    copies (`distinct_orbits`; Farrell, Birkisson and Funke (2015) find the branches
    of a bifurcation this way), and shooting starts from it moved along each
    critical direction (`critical_directions`, both signs) by each of `amplitudes`
    times its size, until `count` orbits are found on that side. At a branch point
    of a symmetric ring the critical directions form a plane in which only a few
    lines, fixed by subgroups of the symmetries, carry branches; a direction off
    them can make Keller's corrector diverge, while a deflated solve from near them
    converges to an orbit of one of the branches.

    **Arguments:**

    - `problem`, `branch`, `point`: as for `switch_branch`.
    - `offset`: the distance in p from the branch point of the two values searched
        (> 0; dimensionless, eq. (6)).
    - `amplitudes`: the sizes of the moves from the followed orbit, relative to its
        state's norm, tried in turn.
    - `count`: the most orbits kept on each side (>= 1).
    - `algorithm`: `PseudoArclength` (the corrector of the followed orbit).

    **Returns:**

    A list of (the problem at an orbit found, the unit direction in (u, p) from the
    branch point to it): pass each to `continuation(new, tangent=t)` to follow that
    branch away from the branch point. Empty if none is found.

    **Raises:**

    `ValidationError` for a point that is not a branch point, an offset that is not
    > 0 or a count < 1.
    """
    if point.kind != "branch point":
        raise ValidationError(f"switch_by_deflation needs a branch point, got a {point.kind}")
    if not offset > 0 or count < 1:
        raise ValidationError(f"switch_by_deflation needs offset > 0 and count >= 1, got "
                              f"{offset!r} and {count!r}")
    ok = np.asarray(branch.converged)
    tangent = branch.tangent[np.nonzero(ok)[0][point.after]]
    directions = critical_directions(problem, point.z, tangent)[:, :-1]
    held = jnp.zeros(point.z.size).at[-1].set(1.0)
    out = []
    for side in (1, -1):
        p = float(point.p) + side * offset
        followed, good, _, _ = _correct(problem, algorithm, point.z.at[-1].set(p), held)
        if not bool(good):
            continue
        here = problem.with_params(problem.at(p))
        known = [followed[:-1]]
        size = float(jnp.linalg.norm(followed[:-2]))
        for amplitude, c, sign in itertools.product(amplitudes, directions, (1, -1)):
            if len(known) > count:
                break
            move = sign * amplitude * size * c / np.linalg.norm(c)
            known += distinct_orbits(here, followed[:-1] + move, known, count=1)
        for u in known[1:]:
            z = jnp.append(u, p)
            out.append((eqx.tree_at(lambda pr: pr.u0, here, u),
                        (z - point.z) / jnp.linalg.norm(z - point.z)))
    return out
