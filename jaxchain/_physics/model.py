"""The vector field of the chain, eq. (5) of the paper, its steady sliding and its
Jacobian. Nothing here knows about solvers."""

import equinox as eqx
import jax
import jax.numpy as jnp
import lineax as lx
from jaxtyping import Array, ArrayLike, Float

from .custom_types import State
from .forces import (DEFAULT_EPS, coupling_energy, coupling_force, friction_coefficient,
                     smoothed_friction_force, stiffness_matrix)
from .params import ChainParams, is_homogeneous_ring
from .._errors import ValidationError


class Model(eqx.Module):
    """What an engine integrates and its observers see as `args`: the chain and the
    smoothing velocity of its friction law, tanh(v_rel/eps) (the smoothed engine's
    `Smoothed.eps`; 0 for the exact engine, which does not smooth).

    **Arguments:**

    - `params`: the chain (`ChainParams`).
    - `eps`: the smoothing velocity, shape () (or one per lane), dimensionless.
    """

    params: ChainParams
    eps: Float[ArrayLike, ""]


def model_field(t, y: State | Float[Array, " 2n"], model: Model):
    """`vector_field` of a `Model`: eq. (5) as diffrax calls it (args = the model)."""
    return vector_field(t, y, model.params, model.eps)


def model_split_field(t, y: State | Float[Array, " 2n"], model: Model):
    """`split_vector_field` of a `Model`, as diffrax calls it (args = the model)."""
    return split_vector_field(t, y, model.params, model.eps)


def vector_field(t, y: State | Float[Array, " 2n"], params: ChainParams,
                 eps: Float[ArrayLike, ""] = DEFAULT_EPS):
    """Right-hand side of eq. (5) of the paper, with the smoothed friction force of
    `smoothed_friction_force` and the coupling of `coupling_force`:

        m_n x_n'' = -2 xi_n x_n' - k_n x_n - (coupling)_n + (P_n/P) F(x_n' - v_d)
                    + f_n(t),

    (m_n = 1 unless `params.mass` is given; f_n the harmonic force of
    `params.forcing`, 0 without one); on the paper's ring (coupling)_n =
    eta_c (2 x_n - x_{n+1} - x_{n-1}), k_n = 1 and P_n = P. For n_osc = 1 on the
    ring the coupling term vanishes (the oscillator is its own neighbour), which
    gives the single mass-on-moving-belt oscillator of Fig. 3(a).

    **Arguments:**

    - `t`: time, dimensionless (eq. 4); read only by a forcing (the paper's chain
        is autonomous).
    - `y`: state of shape (2, n_osc), rows (x, x'), or the same flattened to
        (2 n_osc,).
    - `params`: the chain parameters.
    - `eps`: the smoothing velocity of tanh(v_rel/eps) (> 0), shape (); the
        smoothed engine's (`Smoothed.eps`), `DEFAULT_EPS` by default.

    **Returns:**

    dy/dt, of the same shape as `y`.

    **Raises:**

    `ValidationError` if the shape of `y` does not match `params.n_osc`.
    """
    elastic, friction = split_vector_field(t, y, params, eps)
    return elastic + friction


def split_vector_field(t, y: State | Float[Array, " 2n"], params: ChainParams,
                       eps: Float[ArrayLike, ""] = DEFAULT_EPS):
    """The right-hand side of eq. (5) as (elastic and viscous part, friction part),
    whose sum is `vector_field`: the elastic part (x_n' and -2 xi x_n' - x_n -
    eta_c (2 x_n - x_{n+1} - x_{n-1})) is non-stiff, the friction part (0 and the
    smoothed force) carries the stiffness mu_st/eps. IMEX solvers (diffrax's
    KenCarp) treat the second implicitly (Kennedy & Carpenter (2003), Appl. Numer.
    Math. 44, 139-181).

    **Arguments:** as `vector_field`.

    **Returns:**

    (elastic, friction), each of the shape of `y`.

    **Raises:**

    `ValidationError` if the shape of `y` does not match `params.n_osc`.
    """
    shape = jnp.shape(y)
    n = params.n_osc
    if shape not in ((2, n), (2 * n,)):
        raise ValidationError(f"state must have shape (2, {n}) or ({2 * n},), got {shape}")
    x, v = jnp.reshape(y, (2, n))
    acceleration = -2 * params.xi * v - params.stiffness * x - coupling_force(params, x)
    force = smoothed_friction_force(params, v - params.v_d, eps)
    if params.forcing is not None:
        acceleration = acceleration + params.forcing.force(t)
    if params.mass is not None:
        acceleration, force = acceleration / params.mass, force / params.mass
    elastic = jnp.stack([v, acceleration])
    friction = jnp.stack([jnp.zeros_like(force), force])
    return jnp.reshape(elastic, shape), jnp.reshape(friction, shape)


def steady_sliding(params: ChainParams, eps: Float[ArrayLike, ""] | None = None) -> State:
    """Steady sliding, the fixed point of eq. (5): x_n' = 0 and K x = F(-v_d), K the
    `stiffness_matrix` and F_n(-v_d) = (P_n/P) mu(v_d) the friction force at rest
    (the belt slides under every oscillator), or with `eps` the smoothed force
    (P_n/P) mu(v_d) tanh(v_d/eps) of the smoothed engine's fixed point (equal in
    float64 for v_d/eps > 19). On a homogeneous ring every x_n = F(-v_d)/k;
    otherwise the linear system is solved (lineax, LU).

    **Arguments:**

    - `params`: the chain parameters.
    - `eps`: the smoothing velocity (`vector_field`), or None for the law unsmoothed
        (the exact engine's fixed point, from which initial conditions start).

    **Returns:**

    State of shape (2, n_osc), dimensionless.
    """
    n = params.n_osc
    v_d = jnp.asarray(params.v_d)
    force = (params.load * friction_coefficient(params, -v_d) if eps is None
             else smoothed_friction_force(params, -v_d, eps))
    force = jnp.broadcast_to(force, (n,))
    if is_homogeneous_ring(params):
        x = force / params.stiffness
    else:
        # K is positive definite (ground springs > 0 and couplings >= 0, as
        # `ChainParams` checks), so the LU does not fail; without lineax's check
        # of the result (throw=False) the program holds no host callback and can be
        # kept (`kept_program`).
        operator = lx.MatrixLinearOperator(stiffness_matrix(params))
        x = lx.linear_solve(operator, force, lx.LU(), throw=False).value
    return jnp.stack([x, jnp.zeros_like(x)])


def stick_force(params: ChainParams, x: Float[Array, " n_osc"]) -> Float[Array, " n_osc"]:
    """Friction force that oscillator n needs to stick (x_n' = v_d, x_n'' = 0), from
    eq. (5) of the paper:

        f_n = 2 xi_n v_d + k_n x_n + (coupling)_n,

    (coupling)_n = eta_c (2 x_n - x_{n+1} - x_{n-1}) on the paper's ring
    (`coupling_force`). It depends on the displacements only (the coupling is
    elastic), so whether one oscillator can stick never depends on what its
    neighbours do at the same instant. Stick lasts while |f_n| < (P_n/P) mu(0)
    (`static_friction`).

    **Arguments:**

    - `params`: the chain parameters.
    - `x`: displacements, shape (n_osc,), dimensionless.

    **Returns:**

    f, shape (n_osc,), dimensionless (in units of the normal load P).
    """
    return 2 * params.xi * params.v_d + params.stiffness * x + coupling_force(params, x)


def mechanical_energy(params: ChainParams, y: State) -> Float[Array, ""]:
    """Kinetic plus elastic energy of the chain,

        1/2 sum_n (m_n x_n'^2 + k_n x_n^2) + sum_links `coupling_energy`,

    (on the paper's ring 1/2 sum_n (x_n'^2 + x_n^2 + eta_c (x_{n+1} - x_n)^2)), whose
    rate of change along eq. (5) is the power of friction minus the viscous
    dissipation sum_n 2 xi_n x_n'^2 (the energy balance).

    **Arguments:**

    - `params`: the chain parameters.
    - `y`: state of shape (2, n_osc).

    **Returns:**

    The energy, shape (), dimensionless.
    """
    x, v = y
    kinetic = v**2 if params.mass is None else params.mass * v**2
    if params.boundary == "ring":  # one link per oscillator: one sum, as eq. (5) reads
        return 0.5 * jnp.sum(kinetic + params.stiffness * x**2
                             + params.eta_c * (jnp.roll(x, -1) - x) ** 2)
    return 0.5 * jnp.sum(kinetic + params.stiffness * x**2) + jnp.sum(coupling_energy(params, x))


def jacobian(params: ChainParams, y: State | None = None,
             eps: Float[ArrayLike, ""] = DEFAULT_EPS) -> Float[Array, "2n 2n"]:
    """Jacobian of the flattened vector field of eq. (5), by `jax.jacfwd`.

    **Arguments:**

    - `params`: the chain parameters.
    - `y`: the state, shape (2, n_osc); steady sliding if None.
    - `eps`: the smoothing velocity, as `vector_field` takes it.

    **Returns:**

    Matrix of shape (2 n_osc, 2 n_osc), ordered (x_1..x_N, x_1'..x_N').
    """
    return _jacobian(params, y, as_value(eps))


def as_value(eps):
    """`eps` as a JAX value (None as it is): under `eqx.filter_jit` a Python float
    would be static and compile a program for every value."""
    return None if eps is None else jnp.asarray(eps, dtype=float)


@eqx.filter_jit
def _jacobian(params: ChainParams, y, eps):
    """`jacobian` as one compiled program: called op by op, `jax.jacfwd` of the
    vector field compiles each of its operations on its own (about 2 s on the first
    call, 20 ms on each later one for N = 8)."""
    if y is None:
        y = steady_sliding(params, eps)
    flat = jnp.reshape(y, (-1,))
    return jax.jacfwd(lambda z: vector_field(0.0, z, params, eps))(flat)
