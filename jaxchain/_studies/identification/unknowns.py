"""The parameters an identification fits, and the parametrisation that keeps them
valid: a positive parameter is fitted as its logarithm, and a static coefficient
as its excess over the dynamic one, so that mu_st > mu_d > 0, v0 > 0 and xi > 0
hold for every value of the unknowns, with no clipping."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..._errors import ValidationError
from ..._physics.params import (ChainParams, parameter_lens, parameter_names,
                                parameter_value, revalidated, with_fields)

#: Fields of `ChainParams` a fit may take: each is >= 0 or > 0 (log-parametrised).
#: `v_d` is each record's own, and eps is the fit's smoothing (the eps of the
#: `Smoothed` engine of `IdentifyOptions.engine`), not the rig's.
CHAIN_FITTABLE = ("xi", "eta_c", "stiffness", "load", "mass")

#: The value a log-parametrised start of 0 (a viscous term, a damping) is raised
#: to: the logarithm needs a positive start.
_FLOOR = 1e-3


class Unknowns(eqx.Module):
    """The fitted parameters of a chain and how they map to the unknowns theta of
    the least-squares problem.

    **Fields** (static):

    - `names`: the fitted parameters, in order.
    - `sizes`: their sizes (1 for a scalar; n_osc for a per-oscillator field; m
        for a table's values).
    - `kinds`: per name, `"log"` (theta = log p), `"above:<lower>"` (theta =
        log(p - lower), the static coefficient over the dynamic one) or `"free"`
        (theta = p, a coefficient of either sign).
    """

    names: tuple = eqx.field(static=True)
    sizes: tuple = eqx.field(static=True)
    kinds: tuple = eqx.field(static=True)

    @property
    def size(self) -> int:
        """The number of unknowns theta."""
        return int(sum(self.sizes))

    @property
    def labels(self) -> tuple[str, ...]:
        """One label per unknown: the name, with an index for a vector parameter."""
        return tuple(name if size == 1 else f"{name}[{i}]"
                     for name, size in zip(self.names, self.sizes) for i in range(size))

    def theta(self, params: ChainParams) -> np.ndarray:
        """The unknowns of `params`' values of the fitted parameters, shape (size,)."""
        parts = []
        for name, kind in zip(self.names, self.kinds):
            p = np.asarray(parameter_value(params, name), dtype=float).reshape(-1)
            if kind.startswith("above:"):
                lower = np.asarray(parameter_value(params, kind[6:]), dtype=float)
                p = p - lower.reshape(-1)
            if kind != "free":
                p = np.log(np.where(p > 0, p, _FLOOR))
            parts.append(p)
        return np.concatenate(parts) if parts else np.zeros(0)

    def params(self, base: ChainParams, theta) -> ChainParams:
        """`base` with the fitted parameters set from `theta` (traceable), all at
        once and then validated, so that no intermediate law is out of order; a
        parameter above another is set over that one's new value."""
        values = self.split(theta)
        new = {}
        for i in sorted(range(len(self.names)), key=lambda i: self.kinds[i].startswith("above:")):
            name, kind = self.names[i], self.kinds[i]
            value = values[i] if kind == "free" else jnp.exp(values[i])
            if kind.startswith("above:"):
                lower = new.get(kind[6:], parameter_value(base, kind[6:]))
                value = jnp.reshape(lower, (-1,)) + value
            new[name] = value
        return self.with_values(base, new)

    def with_values(self, base: ChainParams, values) -> ChainParams:
        """`base` with the fitted parameters set to `values` (a dict by name, or one
        vector in the order of `labels`), all at once and then validated."""
        if not isinstance(values, dict):
            values = dict(zip(self.names, self.split(values)))
        changed = base
        for name, value in values.items():
            shape = np.shape(parameter_value(base, name))
            changed = eqx.tree_at(parameter_lens(name, base), changed,
                                  jnp.reshape(value, shape) if isinstance(value, jax.Array)
                                  else np.reshape(np.asarray(value, dtype=float), shape))
        return with_fields(changed, friction=revalidated(changed.friction))

    def values(self, base: ChainParams, theta) -> jnp.ndarray:
        """The fitted parameters' values (traceable) as one vector, in the order of
        `labels`; for the covariance of the parameters by the delta method."""
        params = self.params(base, theta)
        return jnp.concatenate([jnp.reshape(parameter_value(params, name), (-1,))
                                for name in self.names])

    def split(self, theta) -> list:
        """theta cut into one vector per fitted parameter."""
        edges = np.cumsum((0,) + self.sizes)
        return [theta[a:b] for a, b in zip(edges[:-1], edges[1:])]


def unknowns_of(params: ChainParams, fit) -> Unknowns:
    """The `Unknowns` that fit the named parameters of `params` and its friction law.

    **Arguments:**

    - `params`: the chain, with the starting values.
    - `fit`: names, such as ("mu_st", "mu_d", "v0", "xi"): fields of the friction
        law (its `parameter_names`) and of `CHAIN_FITTABLE`.

    **Raises:**

    `ValidationError` for no name, a repeated name, a name that is not a parameter
    of this chain and law, or `v_d` / `eps`.
    """
    names = tuple(fit)
    if not names:
        raise ValidationError("fit: name at least one parameter to fit")
    if len(set(names)) != len(names):
        raise ValidationError(f"fit: a parameter is named twice in {', '.join(names)}")
    law = type(params.friction)
    allowed = CHAIN_FITTABLE + law.parameter_names()
    for name in names:
        if name in ("v_d", "eps"):
            raise ValidationError(f"fit: {name} cannot be fitted (v_d is each record's "
                                  "belt speed; eps is the smoothing of the model, "
                                  "the eps of IdentifyOptions.engine)")
        if name not in allowed or name not in parameter_names(params):
            raise ValidationError(f"fit: unknown parameter {name!r} for the {law.__name__} "
                                  f"law: choose from {', '.join(allowed)}")
        if name == "mass" and params.mass is None:
            raise ValidationError("fit: mass needs the chain's masses (ChainParams(mass=...))")
    rules = law.rules()
    lowers = dict(law.ordered_pairs())
    kinds = []
    for name in names:
        if name in lowers:
            kinds.append(f"above:{lowers[name]}")
        elif name in CHAIN_FITTABLE or rules.get(name, (None, ""))[1] in ("> 0", ">= 0"):
            kinds.append("log")
        else:
            kinds.append("free")
    sizes = tuple(int(np.size(parameter_value(params, name))) for name in names)
    return Unknowns(names=names, sizes=sizes, kinds=tuple(kinds))
