"""The vector field of the ring, eq. (5) of the paper, its steady sliding and its
Jacobian. Nothing here knows about solvers."""

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from ._custom_types import State
from ._friction import smoothed_friction_force
from ._params import ChainParams


def vector_field(t, y: State | Float[Array, " 2n"],
                 params: ChainParams):
    """Right-hand side of eq. (5) of the paper on a ring (periodic boundary
    conditions, oscillator N coupled to oscillator 1), with the smoothed friction
    force of `smoothed_friction_force`:

        x_n'' = -2 xi x_n' - x_n - eta_c (2 x_n - x_{n+1} - x_{n-1}) + F(x_n' - v_d).

    For n_osc = 1 the coupling term vanishes (the oscillator is its own neighbour),
    which gives the single mass-on-moving-belt oscillator of Fig. 3(a).

    **Arguments:**

    - `t`: time (unused; the system is autonomous), dimensionless (eq. 4).
    - `y`: state of shape (2, n_osc), rows (x, x'), or the same flattened to
        (2 n_osc,).
    - `params`: the chain parameters.

    **Returns:**

    dy/dt, of the same shape as `y`.

    **Raises:**

    `ValueError` if the shape of `y` does not match `params.n_osc`.
    """
    elastic, friction = split_vector_field(t, y, params)
    return elastic + friction


def split_vector_field(t, y: State | Float[Array, " 2n"], params: ChainParams):
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

    `ValueError` if the shape of `y` does not match `params.n_osc`.
    """
    shape = jnp.shape(y)
    n = params.n_osc
    if shape not in ((2, n), (2 * n,)):
        raise ValueError(f"state must have shape (2, {n}) or ({2 * n},), got {shape}")
    x, v = jnp.reshape(y, (2, n))
    coupling = 2 * x - jnp.roll(x, 1) - jnp.roll(x, -1)
    elastic = jnp.stack([v, -2 * params.xi * v - x - params.eta_c * coupling])
    force = smoothed_friction_force(params, v - params.v_d)
    friction = jnp.stack([jnp.zeros_like(force), force])
    return jnp.reshape(elastic, shape), jnp.reshape(friction, shape)


def steady_sliding(params: ChainParams) -> State:
    """Steady sliding, the fixed point of eq. (5): x_n = F(-v_d) = mu(v_d) (smoothed:
    mu(v_d) tanh(v_d/eps)), x_n' = 0 for every n.

    **Returns:**

    State of shape (2, n_osc), dimensionless.
    """
    x = smoothed_friction_force(params, -jnp.asarray(params.v_d))
    x = jnp.broadcast_to(x, (params.n_osc,))
    return jnp.stack([x, jnp.zeros_like(x)])


def stick_force(params: ChainParams, x: Float[Array, " n_osc"]) -> Float[Array, " n_osc"]:
    """Friction force that oscillator n needs to stick (x_n' = v_d, x_n'' = 0), from
    eq. (5) of the paper:

        f_n = 2 xi v_d + x_n + eta_c (2 x_n - x_{n+1} - x_{n-1}).

    It depends on the displacements only (the coupling is elastic), so whether one
    oscillator can stick never depends on what its neighbours do at the same instant.
    Stick lasts while |f_n| < mu_st.

    **Arguments:**

    - `params`: the chain parameters.
    - `x`: displacements, shape (n_osc,), dimensionless.

    **Returns:**

    f, shape (n_osc,), dimensionless (in units of the normal load P).
    """
    coupling = 2 * x - jnp.roll(x, 1) - jnp.roll(x, -1)
    return 2 * params.xi * params.v_d + x + params.eta_c * coupling


def mechanical_energy(params: ChainParams, y: State) -> Float[Array, ""]:
    """Kinetic plus elastic energy of the ring,

        1/2 sum_n (x_n'^2 + x_n^2 + eta_c (x_{n+1} - x_n)^2),

    whose rate of change along eq. (5) is the power of friction minus the viscous
    dissipation sum_n 2 xi x_n'^2 (the energy balance).

    **Arguments:**

    - `params`: the chain parameters.
    - `y`: state of shape (2, n_osc).

    **Returns:**

    The energy, shape (), dimensionless.
    """
    x, v = y
    return 0.5 * jnp.sum(v**2 + x**2 + params.eta_c * (jnp.roll(x, -1) - x) ** 2)


def jacobian(params: ChainParams, y: State | None = None) -> Float[Array, "2n 2n"]:
    """Jacobian of the flattened vector field of eq. (5), by `jax.jacfwd`.

    **Arguments:**

    - `params`: the chain parameters.
    - `y`: the state, shape (2, n_osc); steady sliding if None.

    **Returns:**

    Matrix of shape (2 n_osc, 2 n_osc), ordered (x_1..x_N, x_1'..x_N').
    """
    if y is None:
        y = steady_sliding(params)
    flat = jnp.reshape(y, (-1,))
    return jax.jacfwd(lambda z: vector_field(0.0, z, params))(flat)
