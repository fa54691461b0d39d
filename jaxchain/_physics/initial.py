"""Initial conditions: eqs. (8) and (10) of the paper, and user-given states."""

import abc

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float

from .custom_types import State
from .chain import Graph, as_graph
from .model import steady_sliding
from .params import ChainParams
from .._errors import ValidationError


def excited_block(n_osc: int, n_excited: int, boundary: str | Graph = "ring"
                  ) -> Bool[np.ndarray, " n_osc"]:
    """Mask of `n_excited` oscillators around the centre of the chain: the excited
    block of eq. (8), or a patch on any other graph.

    The paper does not say which oscillators it excites, only that the 11th (of 20)
    is always excited (Section 3.3). On a line we take the block that starts at the
    centre oscillator c = N//2 + 1 (1-based; c = 11 for N = 20) and grows
    alternately to the right and to the left: oscillators c - (k-1)//2, ...,
    c + k//2, wrapping around the ring. So k = 1 excites {11}, k = 2 {11, 12}, k = 3
    {10, 11, 12}, and k = 20 the whole ring. An open chain ("free", "fixed") has no
    wrap: a block that would pass its last oscillator is shifted back to end there.

    On any other graph the patch is the k oscillators nearest to the centre by
    graph distance (`Graph.distances`), ties broken by the lower index; the centre
    is oscillator (rows//2) * cols + cols//2 of a lattice (row rows//2, column
    cols//2, 0-based), else oscillator N//2 (0-based).

    **Arguments:**

    - `n_osc`: chain size N (>= 1).
    - `n_excited`: number of excited oscillators k, 0 <= k <= N.
    - `boundary`: the chain's boundary (`BOUNDARIES`) or its `Graph`.

    **Returns:**

    Boolean NumPy array of shape (n_osc,).

    **Raises:**

    `ValidationError` if `n_excited` is outside [0, n_osc], or for an unknown boundary.
    """
    if not 0 <= n_excited <= n_osc:
        raise ValidationError(f"n_excited must lie in [0, {n_osc}], got {n_excited}")
    graph = as_graph(boundary, n_osc)
    mask = np.zeros(n_osc, dtype=bool)
    if not graph.is_line:
        mask[_patch_order(graph)[:n_excited]] = True
        return mask
    centre = n_osc // 2  # 0-based index of oscillator N//2 + 1
    start = centre - (n_excited - 1) // 2
    if graph.kind != "ring":
        start = min(start, n_osc - n_excited)
    mask[(start + np.arange(n_excited)) % n_osc] = True
    return mask


def centre_site(graph: Graph) -> int:
    """The 0-based index of the centre of the chain: (rows//2) * cols + cols//2 on a
    lattice, N//2 otherwise (oscillator 11 of the paper's 20)."""
    if graph.kind == "lattice":
        rows, cols = graph.shape
        return (rows // 2) * cols + cols // 2
    return graph.n_osc // 2


def _patch_order(graph: Graph) -> np.ndarray:
    """The oscillators by graph distance from `centre_site`, ties by index: the
    first k form the excited patch of k sites."""
    distance = graph.distances()[centre_site(graph)]
    return np.lexsort((np.arange(graph.n_osc), distance))


def _alternating_signs(graph: Graph) -> np.ndarray:
    """The signs of the out-of-phase excitation of eq. (8), shape (n_osc,): (-1)^n
    (n from 1) on a line or any links, the checkerboard (-1)^(r + c + 1) on a
    lattice (which is (-1)^n along a single row)."""
    if graph.kind == "lattice":
        rows, cols = graph.shape
        r, c = np.divmod(np.arange(graph.n_osc), cols)
        return (-1.0) ** (r + c + 1)
    return (-1.0) ** np.arange(1, graph.n_osc + 1)


class AbstractInitialCondition(eqx.Module):
    """An initial state of the chain that may depend on the parameters (for example
    on the belt speed, through steady sliding). Batch several by giving the array
    fields a leading axis; `ensemble` vmaps over it. `__call__` is traced
    (`simulate` and `ensemble` compile it): write it with `jax.numpy`."""

    @abc.abstractmethod
    def __call__(self, params: ChainParams) -> State:
        """The initial state, shape (2, n_osc): rows (x, x'), dimensionless."""


class OutOfPhaseExcitation(AbstractInitialCondition):
    """Initial displacements 2 (-1)^n on the excited oscillators, around a base
    displacement, with a common initial velocity: eqs. (8) and (10) of the paper.

        x_n(0) = -s x_ss,n + 2 (-1)^n [n excited],   x_n'(0) = velocity,

    with n = 1..N (1-based, as in the paper) and x_ss the displacement of steady
    sliding (`steady_sliding`; F(-v_d) on the paper's ring, F the smoothed friction
    force, so that -s x_ss = F(s v_d) there). Eq. (8) is s = -1, velocity = 0 (so
    the unexcited oscillators start at steady sliding); eq. (10) is s = +1,
    velocity = 0.56, as printed in the paper.

    **Arguments:**

    - `excited`: boolean mask, shape (n_osc,) (see `excited_block`).
    - `velocity`: the common initial velocity (dimensionless).
    - `base_sign`: s, +1 or -1.
    """

    excited: Bool[ArrayLike, " n_osc"]
    velocity: Float[ArrayLike, ""] = 0.0
    base_sign: float = eqx.field(static=True, default=-1.0)

    @classmethod
    def eq8(cls, excited) -> "OutOfPhaseExcitation":
        """Eq. (8) of the paper: at rest, unexcited oscillators at steady sliding."""
        return cls(excited=np.asarray(excited, dtype=bool), velocity=0.0, base_sign=-1.0)

    @classmethod
    def eq10(cls, excited) -> "OutOfPhaseExcitation":
        """Eq. (10) of the paper: x_n'(0) = 0.56, base displacement F(+v_d)."""
        return cls(excited=np.asarray(excited, dtype=bool), velocity=0.56, base_sign=1.0)

    def __call__(self, params: ChainParams) -> State:
        excited = jnp.asarray(self.excited)
        if excited.shape != (params.n_osc,):
            raise ValidationError(
                f"excited must have shape ({params.n_osc},), got {excited.shape}"
            )
        base = -self.base_sign * steady_sliding(params)[0]
        if params.graph.kind == "lattice":
            signs = jnp.asarray(_alternating_signs(params.graph))
        else:  # as eq. (8) reads
            signs = (-1.0) ** jnp.arange(1, params.n_osc + 1)
        x = base + jnp.where(excited, 2.0 * signs, 0.0)
        v = jnp.broadcast_to(jnp.asarray(self.velocity, dtype=x.dtype), x.shape)
        return jnp.stack([x, v])


def _state_array(value):
    """A user's state as a JAX array (tracers as they are).

    **Raises:** `TypeError` naming y0 when it is not real numbers."""
    if isinstance(value, jax.core.Tracer):
        return value
    try:
        a = np.asarray(value) if not isinstance(value, jax.Array) else value
    except ValueError:  # ragged nested lists
        raise TypeError(f"y0 must be an array of real numbers, got {value!r}") from None
    if a.dtype == bool or not (jnp.issubdtype(a.dtype, jnp.integer)
                               or jnp.issubdtype(a.dtype, jnp.floating)):
        raise TypeError(f"y0 must be an array of real numbers, got dtype {a.dtype}")
    return jnp.asarray(a, dtype=float)


class GivenState(AbstractInitialCondition):
    """A user-given initial state.

    **Arguments:**

    - `y0`: array of shape (2, n_osc) (rows x, x') or (2 n_osc,).

    **Raises:**

    `TypeError` when `y0` is not real numbers; `ValidationError` when called with
    parameters whose `n_osc` does not match the shape.
    """

    y0: Float[Array, "..."] = eqx.field(converter=_state_array)

    def __call__(self, params: ChainParams) -> State:
        n = params.n_osc
        if self.y0.shape not in ((2, n), (2 * n,)):
            raise ValidationError(
                f"y0 must have shape (2, {n}) or ({2 * n},), got {self.y0.shape}"
            )
        return jnp.reshape(self.y0, (2, n)).astype(float)


def batch_length(ics: AbstractInitialCondition) -> int:
    """The number of initial conditions in a batched `ics`: the common leading axis
    of its array fields.

    **Raises:**

    `ValidationError` when the array fields have no common leading axis.
    """
    lengths = {np.shape(x)[0] for x in jax.tree_util.tree_leaves(ics)
               if eqx.is_array(x) and np.ndim(x) > 0}
    if len(lengths) != 1:
        raise ValidationError(f"ics must carry one leading batch axis on its array fields, "
                              f"got leading lengths {sorted(lengths)}")
    return lengths.pop()


@eqx.filter_jit
def initial_states(params: ChainParams, ics: AbstractInitialCondition
                   ) -> Float[Array, "lanes 2 n_osc"]:
    """The initial state of each lane: lane i is `ics[i](params[i])`, so that
    eq. (8) starts from that lane's own steady sliding.

    **Arguments:**

    - `params`: every field of shape (lanes,) (`lane_params`).
    - `ics`: initial conditions batched along the leading axis of their array
        fields, lanes of them.

    **Returns:**

    The states, shape (lanes, 2, n_osc), dimensionless.
    """
    return eqx.filter_vmap(lambda p, ic: ic(p))(params, ics)


def localized_family(n_osc: int, family: str = "eq8", boundary: str | Graph = "ring"
                     ) -> OutOfPhaseExcitation:
    """The paper's staircase of initial conditions: 1, 2, ..., N excited oscillators
    in the block of `excited_block`, by eq. (8) or eq. (10).

    **Arguments:**

    - `n_osc`: ring size N.
    - `family`: "eq8" or "eq10".
    - `boundary`: the chain's boundary (where the block may wrap) or its `Graph`
        (patches, `excited_block`).

    **Returns:**

    An `OutOfPhaseExcitation` batched over its leading axis: `excited` has shape
    (n_osc, n_osc), row k-1 exciting k oscillators.

    **Raises:**

    `ValidationError` for an unknown family.
    """
    if family not in FAMILIES:
        raise ValidationError(f"ics must be one of {sorted(FAMILIES)}, got {family!r}")
    masks = np.stack([excited_block(n_osc, k, boundary) for k in range(1, n_osc + 1)])
    one = FAMILIES[family](masks[0])
    return OutOfPhaseExcitation(
        excited=masks,
        velocity=np.full((n_osc,), one.velocity),
        base_sign=one.base_sign,
    )


FAMILIES = {"eq8": OutOfPhaseExcitation.eq8, "eq10": OutOfPhaseExcitation.eq10}
