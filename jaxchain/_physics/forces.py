"""The forces of eq. (5) on a chain (`ChainParams`): the coupling of the springs
eta_c between neighbours (the one coupling force of the smoothed model, the
non-smooth reference and the energy) and the friction law evaluated with the
chain's loads: smoothed by tanh(v_rel/eps) for the smoothed model, or with the
slip direction for the non-smooth reference (eq. (2))."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .params import ChainParams


def _extensions_along(x, boundary: str, axis: int):
    """The extensions x_right - x_left of the links of the lines of `x` along `axis`
    (a line of `BOUNDARIES`, "periodic" for "ring"), in their link order."""
    if boundary in ("ring", "periodic"):
        return jnp.roll(x, -1, axis) - x
    if boundary == "fixed":
        pad = [(0, 0)] * x.ndim
        pad[axis] = (1, 1)
        x = jnp.pad(x, pad)
    n = x.shape[axis]
    return (jax.lax.slice_in_dim(x, 1, n, axis=axis)
            - jax.lax.slice_in_dim(x, 0, n - 1, axis=axis))


def _force_along(tension, boundary: str, axis: int):
    """The force of the link tensions of the lines along `axis` on their sites: a
    link pulls its left end forward and its right end back."""
    if boundary in ("ring", "periodic"):
        return jnp.roll(tension, 1, axis) - tension
    if boundary == "free":
        pad = [(0, 0)] * tension.ndim
        pad[axis] = (1, 1)
        tension = jnp.pad(tension, pad)
    n = tension.shape[axis]
    return (jax.lax.slice_in_dim(tension, 0, n - 1, axis=axis)
            - jax.lax.slice_in_dim(tension, 1, n, axis=axis))


def _lattice_laplacian(graph, x):
    """sum over each site's links of (x_n - x_other) on a lattice, by shifts of the
    flat x with constant masks (one fused loop, as the ring's eq. (5)): the right
    and left neighbours by rolls of 1 (the other end of the row where a row wraps),
    those below and above by rolls of cols (which wrap a periodic column by
    themselves); a missing neighbour counts 0, a ground link also counts in the
    degree."""
    rows, cols = graph.shape
    across, along = graph.boundary
    n = rows * cols
    r, c = np.divmod(np.arange(n), cols)
    degree = np.zeros(n)
    neighbours = jnp.zeros_like(x)
    for size, position, boundary, step, wrap in ((cols, c, along, 1, cols - 1),
                                                 (rows, r, across, cols, None)):
        for sign, edge in ((1, size - 1), (-1, 0)):
            value = jnp.roll(x, -sign * step)
            inner = position != edge
            if boundary == "periodic":
                if wrap is not None:
                    value = jnp.where(inner, value, jnp.roll(x, sign * wrap))
                degree += 1.0
            else:
                value = value * inner
                degree += 1.0 if boundary == "fixed" else inner
            neighbours = neighbours + value
    return degree * x - neighbours


def _lattice_stiffnesses(params: ChainParams):
    """eta_c of a lattice's links along the rows, shape () or (rows, links per row),
    and along the columns, shape () or (links per column, cols)."""
    eta = params.eta_c
    if jnp.ndim(eta) == 0:
        return eta, eta
    rows, cols = params.graph.shape
    split = params.graph.row_links()
    return (jnp.reshape(eta[:split], (rows, -1)),
            jnp.reshape(eta[split:], (cols, -1)).T)


def _link_extensions(params: ChainParams, x: Float[Array, " n_osc"]
                     ) -> Float[Array, " n_links"]:
    """The extension of each coupling spring, x_right - x_left (the ground's
    displacement is 0), in the link order of the chain's `Graph`.

    **Arguments:**

    - `params`: the chain parameters (`graph`).
    - `x`: displacements, shape (n_osc,), dimensionless.

    **Returns:**

    Shape (n_links,). A line's and a lattice's links are taken by shifts of x (along
    each direction of the lattice); any other graph's by its incidence matrix
    (`Graph.incidence`, a constant of the compiled program).
    """
    graph = params.graph
    if graph.kind == "ring":
        return jnp.roll(x, -1) - x
    if graph.kind == "free":
        return x[1:] - x[:-1]
    if graph.kind == "fixed":
        ground = jnp.zeros((1,), dtype=x.dtype)
        return jnp.diff(jnp.concatenate([ground, x, ground]))
    if graph.kind == "lattice":
        grid = jnp.reshape(x, graph.shape)
        across, along = graph.boundary
        return jnp.concatenate([_extensions_along(grid, along, 1).ravel(),
                                _extensions_along(grid, across, 0).T.ravel()])
    return jnp.asarray(graph.incidence()) @ x


def coupling_force(params: ChainParams, x: Float[Array, " n_osc"]
                   ) -> Float[Array, " n_osc"]:
    """The restoring force of the coupling springs on each oscillator, the coupling
    term of eq. (5) of the paper generalised to any graph and to one eta_c per
    link: the sum over oscillator n's links l of eta_l (x_n - x_other(l)).

    On the homogeneous ring (scalar eta_c) this is eq. (5)'s
    eta_c (2 x_n - x_{n+1} - x_{n-1}), evaluated in that form, so that the paper's
    runs are reproduced bit for bit. A line or a lattice is evaluated by shifts
    along each direction; any other graph by its incidence matrix D (D^T (eta D x)).

    **Arguments:**

    - `params`: the chain parameters (`graph`, `eta_c` of shape () or (n_links,)).
    - `x`: displacements, shape (n_osc,), dimensionless.

    **Returns:**

    Shape (n_osc,), dimensionless (in units of the normal load P); it enters eq. (5)
    with a minus sign.
    """
    graph = params.graph
    if graph.kind == "ring" and jnp.ndim(params.eta_c) == 0:
        return params.eta_c * (2 * x - jnp.roll(x, 1) - jnp.roll(x, -1))
    if graph.is_line:
        tension = params.eta_c * _link_extensions(params, x)
        if graph.kind == "ring":  # link n pulls oscillator n forward, n+1 back
            return jnp.roll(tension, 1) - tension
        if graph.kind == "free":
            nothing = jnp.zeros((1,), dtype=tension.dtype)
            tension = jnp.concatenate([nothing, tension, nothing])
        return tension[:-1] - tension[1:]
    if graph.kind == "lattice" and jnp.ndim(params.eta_c) == 0:
        return params.eta_c * _lattice_laplacian(graph, x)
    if graph.kind == "lattice":
        grid = jnp.reshape(x, graph.shape)
        across, along = graph.boundary
        eta_along, eta_across = _lattice_stiffnesses(params)
        force = (_force_along(eta_along * _extensions_along(grid, along, 1), along, 1)
                 + _force_along(eta_across * _extensions_along(grid, across, 0), across, 0))
        return jnp.reshape(force, (-1,))
    tension = params.eta_c * _link_extensions(params, x)
    return jnp.asarray(graph.incidence()).T @ tension


def coupling_energy(params: ChainParams, x: Float[Array, " n_osc"]
                    ) -> Float[Array, " n_links"]:
    """The elastic energy of each coupling spring, eta_l (extension)^2 / 2, shape
    (n_links,), dimensionless (in units of P x_0). Its gradient in x is
    `coupling_force`."""
    return 0.5 * params.eta_c * _link_extensions(params, x) ** 2


def stiffness_matrix(params: ChainParams) -> Float[Array, "n_osc n_osc"]:
    """The stiffness matrix K of the linear chain, x'' = -K x + ...: the ground
    springs (`stiffness`, 1 + delta_n in eq. (5)) on the diagonal plus the Jacobian
    of `coupling_force` (by `jax.jacfwd`). Symmetric; its eigenvalues are the
    squared natural frequencies of the undamped chain.

    **Returns:**

    Shape (n_osc, n_osc), dimensionless.
    """
    return _stiffness_matrix(params)


@eqx.filter_jit
def _stiffness_matrix(params: ChainParams) -> Float[Array, "n_osc n_osc"]:
    """`stiffness_matrix` as one compiled program (not op by op)."""
    n = params.n_osc
    coupling = jax.jacfwd(lambda x: coupling_force(params, x))(jnp.zeros(n))
    return jnp.diag(jnp.broadcast_to(params.stiffness, (n,))) + coupling


def friction_coefficient(params: ChainParams, v_rel: Float[ArrayLike, "*shape"]
                         ) -> Float[Array, "*shape"]:
    """The friction coefficient mu(v_rel) of the chain's law (`params.friction`),
    eq. (1) of the paper by default: mu_d + (mu_st - mu_d) exp(-|v_rel| / v0).

    **Arguments:**

    - `params`: the chain parameters.
    - `v_rel`: relative velocity x' - v_d, shape () or (n_osc,), dimensionless.

    **Returns:**

    mu, of the broadcast shape of `v_rel` and the law's fields.
    """
    return params.friction(v_rel)


#: The default smoothing velocity of the smoothed engine, eps in tanh(v_rel/eps)
#: (dimensionless, a fraction of x_0 omega_n). Chosen by the work-precision study
#: against the exact engine (documentation, "Choice of eps and solver"): the
#: largest eps whose amplitudes stay within 1 % of the exact ones on every scene
#: (at eps = 3e-3 the case v_d = 1.75, eq. (10), k = 20 falls to steady sliding
#: instead of the exact engine's 10 oscillators on the HALC). Smaller eps cost
#: more: the stick phase stiffens (stiffness about mu_st/eps) and the step count
#: grows as 1x, 2x, 6x and 30x for eps = 1e-2, 3e-3, 1e-3 and 3e-4.
DEFAULT_EPS = 1e-3


def smoothed_friction_force(params: ChainParams, v_rel: Float[ArrayLike, "*shape"],
                            eps: Float[ArrayLike, ""] = DEFAULT_EPS) -> Float[Array, "*shape"]:
    """Smoothed friction force F_n = -(P_n/P) mu(v_rel) tanh(v_rel / eps), in units
    of the nominal normal load P.

    This is eq. (2) of the paper with sign(v_rel) replaced by tanh(v_rel / eps), and
    scaled by each oscillator's normal load `params.load` (1 by default). The stick
    phase becomes a stiff slip at |v_rel| ~ eps, of stiffness about P_n mu(0)/eps.

    **Arguments:**

    - `params`: the chain parameters (its friction law and `load`).
    - `v_rel`: relative velocity x' - v_d, shape () or (n_osc,), dimensionless.
    - `eps`: the smoothing velocity (> 0), shape (), dimensionless; the smoothed
        engine's (`Smoothed.eps`).

    **Returns:**

    F, of the broadcast shape, dimensionless (F/P in eq. (6)).
    """
    return -(params.load * friction_coefficient(params, v_rel)) * jnp.tanh(v_rel / eps)


def slip_friction_force(params: ChainParams, v_rel: Float[ArrayLike, "*shape"],
                        direction: Float[ArrayLike, "*shape"]) -> Float[Array, "*shape"]:
    """Friction force in slip, F = -(P_n/P) mu(|v_rel|) sign(v_rel), eq. (2) of the
    paper, with sign(v_rel) given as the slip `direction` (+1 or -1) of the
    non-smooth reference. Taking the sign from the slip mode, not from v_rel, keeps
    the force smooth within a slip phase, up to and through the zero of v_rel where
    the phase ends (the event is then located on a smooth function).

    **Arguments:**

    - `params`: the chain parameters (its friction law and `load`).
    - `v_rel`: relative velocity x' - v_d, dimensionless.
    - `direction`: slip direction, +1 or -1, broadcastable against `v_rel`.

    **Returns:**

    F, of the broadcast shape, dimensionless (F/P in eq. (6)).

    The law is evaluated at the slip speed direction * v_rel by
    `AbstractFrictionLaw.of_slip_speed` (mu(|v_rel|), with the derivative of the
    phase's side where it begins, at v_rel = 0).
    """
    return -(params.load * params.friction.of_slip_speed(direction * v_rel)) * direction


def static_friction(params: ChainParams) -> Float[Array, "*shape"]:
    """The bound of the set-valued stick condition, |F_n| <= (P_n/P) mu(0), for each
    oscillator (shape () for a homogeneous chain, else (n_osc,))."""
    return params.load * params.friction.static()
