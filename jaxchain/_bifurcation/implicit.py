"""Derivatives of a root of G(z, args) = 0 by the implicit function theorem, in
forward and in reverse mode, for a G that JAX differentiates in forward mode only
(a shooting residual integrates with diffrax's `ForwardMode`, whose loop cannot be
transposed)."""

from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.tree_util as jtu


@eqx.filter_custom_jvp
def implicit_root(fn: Callable, solve: Callable, start, args):
    """The root z of `fn(z, args) = 0` that `solve(fn, start, args)` finds, as
    (z, converged), differentiable in `args` (not in `start`) by the implicit
    function theorem:

        dz = -(dG/dz)^-1 (dG/dargs) dargs.

    Both Jacobians are built in forward mode at the root (`jax.jacfwd`), dG/dargs
    only over the leaves of `args` that carry a tangent (one column per scalar of
    them: the parameter differentiated, not the whole chain), so that the
    tangent is a product of matrices and a linear solve: `jax.jvp` and `jax.grad`
    both work, whereas the transpose of a forward-mode pass through diffrax's loop
    (what `optx.ImplicitAdjoint` asks for in reverse mode) does not exist. Where
    `solve` did not converge, the derivative is NaN.

    **Arguments:**

    - `fn`: the residual G(z, args), of shape (n,) for z of shape (n,).
    - `solve`: `solve(fn, start, args) -> (z, converged)`, for example Newton's
        method.
    - `start`: the starting point, shape (n,).
    - `args`: a pytree of parameters (a `ContinuationProblem`, a `ChainParams`).

    **Returns:**

    (z of shape (n,), converged, a boolean of shape ()).
    """
    return solve(fn, start, args)


@implicit_root.def_jvp
def _implicit_root_jvp(primals, tangents):
    fn, solve, start, args = primals
    t_args = tangents[3]
    z, ok = implicit_root(fn, solve, start, args)
    leaves, treedef = jtu.tree_flatten(args)
    t_leaves = ([None] * len(leaves) if t_args is None else treedef.flatten_up_to(t_args))
    active = [i for i, t in enumerate(t_leaves) if t is not None]
    if not active:
        return (z, ok), (None, None)
    theta = jnp.concatenate([jnp.ravel(leaves[i]) for i in active])
    d_theta = jnp.concatenate([jnp.ravel(jnp.asarray(t_leaves[i])) for i in active])
    sizes = [jnp.size(leaves[i]) for i in active]
    splits = [sum(sizes[:k + 1]) for k in range(len(sizes) - 1)]

    def residual(z, theta):
        new = list(leaves)
        for i, piece in zip(active, jnp.split(theta, splits)):
            new[i] = jnp.reshape(piece, jnp.shape(leaves[i]))
        return fn(z, jtu.tree_unflatten(treedef, new))

    g_z = jax.jacfwd(residual, argnums=0)(z, theta)
    g_theta = jax.jacfwd(residual, argnums=1)(z, theta)
    scale = jnp.where(ok, 1.0, jnp.nan)  # linear in d_theta: NaN in reverse mode too
    dz = -scale * jnp.linalg.solve(g_z, g_theta @ d_theta)
    return (z, ok), (dz, None)
