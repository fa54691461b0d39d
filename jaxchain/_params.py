"""Physical parameters of the chain (eqs. (4)-(7) of the paper)."""

import dataclasses
from collections.abc import Callable

import equinox as eqx
import jax
import numpy as np
from jaxtyping import ArrayLike


def _as_array(value):
    """A parameter value as a float64 NumPy array (a leaf that `eqx.filter_jit`
    traces, so that a new value does not recompile), or the tracer itself."""
    if isinstance(value, jax.core.Tracer) or isinstance(value, jax.Array):
        return value
    try:
        kind = np.asarray(value).dtype.kind
    except ValueError:  # ragged nested lists
        kind = "O"
    if kind not in "iuf":  # booleans, strings, None, ...: refused by the check
        return np.asarray(value, dtype=object)
    return np.asarray(value, dtype=np.float64)


def _concrete(value) -> np.ndarray | None:
    """`value` as a NumPy array, or None when it is a tracer (checked later by
    whoever traces it)."""
    if isinstance(value, jax.core.Tracer):
        return None
    return np.asarray(value, dtype=float)


class ChainParams(eqx.Module):
    """Dimensionless parameters of the ring of friction-excited oscillators, eq. (5) of
    the paper *Multiple spatially localized dynamical states in friction-excited
    oscillator chains*.

    All quantities are dimensionless as in eqs. (4)-(6): displacements in units of
    x_0 = P/k, velocities in units of x_0*omega_n, time in units of 1/omega_n.

    **Arguments:**

    - `n_osc`: number of oscillators N on the ring (static, >= 1).
    - `xi`: damping ratio (>= 0).
    - `mu_d`: dynamic friction coefficient, the limit of mu for large sliding speed
        (> 0).
    - `mu_st`: static friction coefficient mu(0) (>= mu_d).
    - `v0`: reference velocity of the exponential decay in eq. (1) (> 0).
    - `eta_c`: nearest-neighbour coupling stiffness k_c/k (>= 0).
    - `v_d`: belt speed (> 0; a belt moving the other way is the mirror image
        x -> -x).
    - `eps`: velocity scale of the tanh smoothing of sign(v_rel) (> 0).

    The defaults are eq. (7) of the paper (xi = 0.05, mu_d = 0.5, mu_st/mu_d = 2,
    v0 = 0.5) with eta_c = 0.01, N = 20 and v_d = 1.5, the scene of Fig. 4.

    The default `eps = 1e-3` is chosen from the work-precision study against the
    event-driven non-smooth reference (README, "Choice of eps and solver"): it is
    the largest eps whose amplitudes stay within 1 % of the reference on every
    periodic state of the cross-check grid, n_HALC included (0.23 % on the chain
    scene; at eps = 3e-3 the case v_d = 1.75, eq. (10), k = 20 falls to steady
    sliding instead of the reference's 10 oscillators on the HALC). Smaller eps
    cost more: the stick phase stiffens (stiffness about mu_st/eps), and the step
    count grows as 1x, 2x, 6x and 30x for eps = 1e-2, 3e-3, 1e-3 and 3e-4 on the
    Fig. 4 scene.

    Fields other than `n_osc` are stored as float64 arrays (JAX arrays or tracers
    are kept as they are, for example under `jax.vmap`), so that `eqx.filter_jit`
    traces them: a new value of v_d, eps or xi does not recompile. Only concrete
    values are validated. Change a field with `with_parameter`, which validates.

    **Raises:**

    `ValueError` naming the field for a non-finite value, n_osc < 1, xi < 0,
    mu_d <= 0, mu_st < mu_d, v0 <= 0, eta_c < 0, v_d <= 0 or eps <= 0.
    """

    n_osc: int = eqx.field(static=True, default=20)
    xi: ArrayLike = eqx.field(converter=_as_array, default=0.05)
    mu_d: ArrayLike = eqx.field(converter=_as_array, default=0.5)
    mu_st: ArrayLike = eqx.field(converter=_as_array, default=1.0)
    v0: ArrayLike = eqx.field(converter=_as_array, default=0.5)
    eta_c: ArrayLike = eqx.field(converter=_as_array, default=0.01)
    v_d: ArrayLike = eqx.field(converter=_as_array, default=1.5)
    eps: ArrayLike = eqx.field(converter=_as_array, default=1e-3)

    def __check_init__(self):
        if isinstance(self.n_osc, bool) or not isinstance(self.n_osc, (int, np.integer)):
            raise ValueError(f"ChainParams.n_osc must be an integer, got {self.n_osc!r}")
        if self.n_osc < 1:
            raise ValueError(f"ChainParams.n_osc must be >= 1, got {self.n_osc!r}")
        rules = {
            "xi": (lambda a: a >= 0, ">= 0"),
            "mu_d": (lambda a: a > 0, "> 0"),
            "mu_st": (lambda a: True, ""),
            "v0": (lambda a: a > 0, "> 0"),
            "eta_c": (lambda a: a >= 0, ">= 0"),
            "v_d": (lambda a: a > 0, "> 0"),
            "eps": (lambda a: a > 0, "> 0"),
        }
        for name, (ok, requirement) in rules.items():
            value = getattr(self, name)
            if isinstance(value, np.ndarray) and value.dtype == object:
                raise TypeError(f"ChainParams.{name} must be a real number (or an array "
                                f"of them), got {value.tolist()!r}")
            a = _concrete(value)
            if a is None:
                continue
            shown = a.item() if a.ndim == 0 else a
            if not np.all(np.isfinite(a)):
                raise ValueError(f"ChainParams.{name} must be finite, got {shown!r}")
            if not np.all(ok(a)):
                raise ValueError(f"ChainParams.{name} must be {requirement}, got {shown!r}")
        mu_st, mu_d = _concrete(self.mu_st), _concrete(self.mu_d)
        if mu_st is not None and mu_d is not None and not np.all(mu_st >= mu_d):
            raise ValueError(
                f"ChainParams.mu_st must be >= mu_d = {mu_d.tolist()!r}, got {mu_st.tolist()!r}"
            )


class _Field(eqx.Module):
    """The lens of one named field: equal names compare and hash equal, so that a
    jitted function taking the lens compiles once per name."""

    name: str = eqx.field(static=True)

    def __call__(self, params):
        return getattr(params, self.name)


def parameter_lens(where: Callable | str) -> Callable:
    """The lens of a parameter given by name (`"xi"`) or already as a lens.

    **Raises:**

    `ValueError` for an unknown name.
    """
    if not isinstance(where, str):
        return where
    names = [f.name for f in dataclasses.fields(ChainParams) if f.name != "n_osc"]
    if where not in names:
        raise ValueError(f"unknown parameter {where!r}: choose one of {', '.join(names)}")
    return _Field(where)


def parameter_name(where: Callable | str) -> str:
    """The name of the one `ChainParams` field that `where` picks: `where` itself
    when it is a name, or else found by applying the lens to parameters whose
    fields hold distinct values. A sweep keys and labels its results by this name,
    never by the lens (two lambdas cannot be compared by content).

    **Arguments:**

    - `where`: a field name such as `"eta_c"`, or a lens such as `lambda p: p.eta_c`.

    **Returns:**

    The field name.

    **Raises:**

    `ValueError` for an unknown name, for n_osc (it sets the shapes: it cannot vary
    within one compiled run), or for a lens that does not return one field.
    """
    names = [f.name for f in dataclasses.fields(ChainParams) if f.name != "n_osc"]
    if isinstance(where, str):
        parameter_lens(where)  # raises for an unknown name
        return where
    probe = ChainParams(**{name: 0.125 * (i + 1) for i, name in enumerate(names)})
    try:
        picked = where(probe)
    except Exception as err:
        raise ValueError(f"where must pick one field of ChainParams, got a lens that "
                         f"raised {type(err).__name__}: {err}") from None
    if picked is probe.n_osc and isinstance(picked, int):
        raise ValueError("n_osc cannot be swept: it sets the shapes of a compiled run; "
                         "run one sweep per n_osc")
    for name in names:
        if picked is getattr(probe, name):
            return name
    raise ValueError(f"where must pick one field of ChainParams ({', '.join(names)}), "
                     f"got a lens that returns {picked!r}")


def parameter_value(params: ChainParams, where: Callable | str):
    """The value of the parameter `where` (a name or a lens) in `params`."""
    return parameter_lens(where)(params)


def with_parameter(params: ChainParams, where: Callable | str, value) -> ChainParams:
    """`params` with one parameter set to `value`, validated like a new `ChainParams`.
    This is the one way jaxchain changes a parameter (a bare `eqx.tree_at` would skip
    the validation and could leave a Python float, which `eqx.filter_jit` treats as
    static).

    **Arguments:**

    - `params`: the chain parameters.
    - `where`: the field, as a lens such as `lambda p: p.v_d` (as `eqx.tree_at`
        takes it) or as its name, `"v_d"`.
    - `value`: the new value: a number, an array or a tracer.

    **Returns:**

    A new `ChainParams`.

    **Raises:**

    `ValueError` naming the field for a bad value, or for an unknown field name.
    """
    changed = eqx.tree_at(parameter_lens(where), params, value)
    return ChainParams(**{f.name: getattr(changed, f.name) for f in dataclasses.fields(changed)})
