"""The bistable range of the exact switch model: the Hopf point of steady sliding and
the grazing point where the single oscillator's stick-slip cycle ends, and both
against xi and mu_st/mu_d, in the layout of the smoothed model's `bistable_range`."""

import jax.numpy as jnp
import numpy as np

from .._bifurcation.existence import stick_slip_existence_limit
from .._bifurcation.grazing import (GrazingPoint, grazing_curve, grazing_slope,
                                    stick_slip_grazing)
from .._bifurcation.hopf import hopf_speed
from .._bifurcation.two_parameter import BoundaryCurves
from .._errors import ValidationError
from .._physics.friction import ExponentialDecay
from .._physics.params import ChainParams, chain_or_default, single_oscillator, with_parameter
from .._physics.record import chain_record


def _check_grids(**grids) -> None:
    """Each grid, by name, increasing and positive; else `ValidationError`."""
    for name, values in grids.items():
        values = np.asarray(values, dtype=float)
        if values.ndim != 1 or values.size == 0 or values.min() <= 0 or np.any(
                np.diff(values) <= 0):
            raise ValidationError(f"{name} must be increasing positive numbers, got "
                                  f"{values.tolist()}")


def grazing_range(params: ChainParams | None = None, *, xi_values,
                  ratio_values) -> tuple[dict, list]:
    """The edges of the bistable range of the exact switch model for the chain's first
    oscillator (`single_oscillator`): the Hopf point of steady sliding (`hopf_speed`:
    the closed form of eq. (1), which the exact model has, since steady sliding
    slips away from v_rel = 0) and the grazing point where the stick-slip cycle ends
    (`stick_slip_grazing`, Newton's method on its defining condition), and both
    against xi and, for eq. (1), mu_st/mu_d (`grazing_curve`), the grazing value's
    derivatives by the implicit function theorem (`grazing_slope`). Beside each
    grazing value, the closed-form existence limit (`stick_slip_existence_limit`),
    an independent route to the same point.

    **Arguments:**

    - `params`: the chain (the paper's ring where None); its first oscillator is
        analysed.
    - `xi_values`, `ratio_values`: grids of xi and of mu_st/mu_d, increasing.

    **Returns:**

    (summary, curves): the summary in the keys of `bistable_range`'s, the grazing
    point in those of the fold (`fold_vd`, `xi_curve`, `ratio_curve`, ...), with
    `boundary` "grazing"; and the `BoundaryCurves` in xi and mu_st (None for
    another friction law), for `plot_bistable_region`.

    **Raises:**

    `ValidationError` for grids that are not increasing and positive; `ValueError`
    when steady sliding has no Hopf point to start from.
    """
    params = chain_or_default(params)
    _check_grids(xi_values=xi_values, ratio_values=ratio_values)
    single = single_oscillator(params)
    point = stick_slip_grazing(single)
    limit = stick_slip_existence_limit(single)
    grids = [("xi", "xi", np.asarray(xi_values, dtype=float), 1.0)]
    if isinstance(single.friction, ExponentialDecay):
        mu_d = float(single.friction.mu_d)
        grids.append(("mu_st", "mu_st/mu_d", mu_d * np.asarray(ratio_values, dtype=float),
                      1 / mu_d))
    summary = {
        "engine": "exact", "boundary": "grazing",
        "hopf_vd": hopf_speed(single), "fold_vd": float(point.value),
        "grazing_arc_time": float(point.time),
        "existence_limit_nonsmooth": limit,
        "fold_minus_existence_limit": float(point.value) - limit,
        "d_fold_vd_d_xi": grazing_slope(point, "xi"),
    }
    curves = []
    for where, name, values, scale in grids:
        curve = grazing_curve(point, where, values)
        hopf = [hopf_speed(with_parameter(single, where, v)) for v in values]
        limits = [stick_slip_existence_limit(with_parameter(single, where, v)) for v in values]
        fold = [float(v) if ok else None for v, ok in
                zip(np.asarray(curve.value), np.asarray(curve.converged))]
        slopes = [grazing_slope(_point(curve, where, values[k], k), where)
                  if fold[k] is not None else None for k in range(values.size)]
        key = "xi_curve" if where == "xi" else "ratio_curve"
        summary[key] = {
            name: (values * scale).tolist(), "hopf_vd": hopf, "fold_vd": fold,
            "existence_limit_nonsmooth": limits,
            "fold_minus_existence_limit": [None if f is None else f - e
                                           for f, e in zip(fold, limits)],
            "d_fold_vd": [None if d is None else d / scale for d in slopes],
        }
        if where == "mu_st":
            summary["d_fold_vd_d_ratio"] = grazing_slope(point, "mu_st") * mu_d
        nan = jnp.full(values.size, jnp.nan)
        curves.append(BoundaryCurves(
            values=jnp.asarray(values), hopf_vd=jnp.asarray(hopf),
            fold_vd=jnp.asarray([np.nan if f is None else f for f in fold]),
            d_hopf=nan, d_fold=jnp.asarray([np.nan if d is None else d for d in slopes]),
            converged=curve.converged, solutions=jnp.full((values.size, 1), jnp.nan),
            branches=()))
    summary["chain"] = chain_record(params)
    return summary, curves + [None] * (2 - len(curves))


def _point(curve: GrazingPoint, other: str, value: float, k: int) -> GrazingPoint:
    """The k-th point of a grazing curve in `other` (at `value`) as a `GrazingPoint`
    of its own, its `params` at both values."""
    params = with_parameter(with_parameter(curve.params, other, value), curve.where,
                            curve.value[k])
    return GrazingPoint(params=params, where=curve.where, value=curve.value[k],
                        time=curve.time[k], residual=curve.residual[k],
                        converged=curve.converged[k])
