"""The exponentially decaying friction law, eqs. (1)-(2) of the paper."""

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from ._params import ChainParams


def friction_coefficient(params: ChainParams, v_rel: Float[ArrayLike, "*shape"]
                         ) -> Float[Array, "*shape"]:
    """Friction coefficient mu(v_rel) = mu_d + (mu_st - mu_d) exp(-|v_rel| / v0),
    eq. (1) of the paper.

    **Arguments:**

    - `params`: the chain parameters (uses `mu_d`, `mu_st`, `v0`).
    - `v_rel`: relative velocity x' - v_d, any shape, dimensionless.

    **Returns:**

    mu, of the same shape as `v_rel`. mu(0) = mu_st, and mu -> mu_d as |v_rel| -> oo.
    """
    return params.mu_d + (params.mu_st - params.mu_d) * jnp.exp(
        -jnp.abs(v_rel) / params.v0
    )


def smoothed_friction_force(params: ChainParams, v_rel: Float[ArrayLike, "*shape"]
                            ) -> Float[Array, "*shape"]:
    """Smoothed friction force F = -mu(v_rel) tanh(v_rel / eps), in units of the
    normal load P.

    This is eq. (2) of the paper with sign(v_rel) replaced by tanh(v_rel / eps). The
    stick phase becomes a stiff slip at |v_rel| ~ eps, of stiffness about mu_st/eps.

    **Arguments:**

    - `params`: the chain parameters (uses `mu_d`, `mu_st`, `v0`, `eps`).
    - `v_rel`: relative velocity x' - v_d, any shape, dimensionless.

    **Returns:**

    F, of the same shape as `v_rel`, dimensionless (F/P in eq. (6)).
    """
    return -friction_coefficient(params, v_rel) * jnp.tanh(v_rel / params.eps)


def slip_friction_force(params: ChainParams, v_rel: Float[ArrayLike, "*shape"],
                        direction: Float[ArrayLike, "*shape"]) -> Float[Array, "*shape"]:
    """Friction force in slip, F = -mu(|v_rel|) sign(v_rel), eq. (2) of the paper,
    with sign(v_rel) given as the slip `direction` (+1 or -1) of the non-smooth
    reference. Taking the sign from the slip mode, not from v_rel, keeps the force
    smooth within a slip phase, up to and through the zero of v_rel where the phase
    ends (the event is then located on a smooth function).

    **Arguments:**

    - `params`: the chain parameters (uses `mu_d`, `mu_st`, `v0`).
    - `v_rel`: relative velocity x' - v_d, dimensionless.
    - `direction`: slip direction, +1 or -1, broadcastable against `v_rel`.

    **Returns:**

    F, of the broadcast shape, dimensionless (F/P in eq. (6)).
    """
    return -friction_coefficient(params, v_rel) * direction
