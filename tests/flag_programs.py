"""A small program of each kind that jaxchain builds, run in a process of its own
by tests/test_setup.py once with jaxchain's XLA flag (`jc.XLA_FLAGS`) and once
without, whose results it compares: both engines, forward and reverse mode, under
`jax.jit` and `jax.vmap` (the smoothed engine has no reverse mode), the shooting residuals
of both and their Jacobians (what Newton's method and continuation compile), the
Hopf point and its derivative. Prints
{name: values} as JSON."""

import json
import sys

import jaxchain as jc

jc.configure()

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

#: A ring of four from a state whose first switches on [0, 6] are of every kind
#: (tests/test_saltation.py), and weights of its final state.
Y0 = jnp.array([[3.0, -0.5, 0.3, -1.0], [1.3, 0.2, 1.5, -0.4]])
WEIGHTS = jnp.array([[1.0, -0.7, 0.4, 0.2], [0.3, 0.5, -0.9, 0.6]])
T = 6.0
#: The integration tolerances of the programs below (rtol = atol).
TOL = 1e-10


def exact(v_d, xi, adjoint="forward"):
    """sum(WEIGHTS * y(T)) on the ring of four, by the exact engine."""
    options = jc.NonsmoothOptions.reference(t_end=T, transient=0.0, adjoint=adjoint,
                                            rtol=TOL, atol=TOL)
    ys = jc.Exact(options).flow(jc.ChainParams(n_osc=4, v_d=v_d, xi=xi), Y0, jnp.array([T]))
    return jnp.sum(WEIGHTS * ys[0])


SHOOTING = jc.Shooting(jc.Smoothed(eps=1e-2).for_orbits(TOL, TOL))
EXACT_SHOOTING = jc.Shooting(jc.Exact().for_orbits(TOL, TOL))
#: The unknowns of shooting: the start Y0 and the period T.
U = jnp.concatenate([jnp.ravel(Y0), jnp.array([T])])


def smoothed(v_d, xi):
    """The shooting residual of the smoothed engine (its flow over a period T from
    Y0, minus Y0), weighted: one number."""
    params = jc.ChainParams(n_osc=4, v_d=v_d, xi=xi)
    return jnp.sum(jnp.ravel(WEIGHTS) * SHOOTING.residual(U, params)[:8])


def hopf(xi):
    return jc.hopf_vd(jc.ChainParams(n_osc=4, v_d=1.5, xi=xi))


speeds = jnp.array([1.2, 1.4])
results = {
    "exact, jit": jax.jit(exact)(1.2, 0.05),
    "exact shooting, its Jacobian (forward mode), jit": jax.jit(jax.jacfwd(
        EXACT_SHOOTING.residual))(U, jc.ChainParams(n_osc=4, v_d=1.2)),
    "exact, reverse mode, jit": jax.jit(jax.grad(lambda v, x: exact(v, x, "reverse"),
                                                 argnums=(0, 1)))(1.2, 0.05),
    "exact, vmap": jax.jit(jax.vmap(exact, in_axes=(0, None)))(speeds, 0.05),
    "smoothed, jit": jax.jit(smoothed)(1.2, 0.05),
    "smoothed, forward mode, jit": jax.jit(jax.jacfwd(smoothed, argnums=(0, 1)))(1.2, 0.05),
    "smoothed, vmap": jax.jit(jax.vmap(smoothed, in_axes=(0, None)))(speeds, 0.05),
    "Hopf point and its derivative": (hopf(0.05), jax.grad(hopf)(0.05)),
}
json.dump({name: np.concatenate([np.ravel(v) for v in jax.tree.leaves(value)]).tolist()
           for name, value in results.items()}, sys.stdout)
