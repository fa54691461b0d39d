"""Physical units: a chain given in SI units made dimensionless as eqs. (4)-(6) of
the paper do it, and results converted back."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from .._errors import ValidationError
from .params import ChainParams
from .scales import Scales

if TYPE_CHECKING:  # heavy: imported where they are used
    import xarray as xr

#: The SI unit each argument of `from_physical` is read in (pint's spelling).
SI_UNITS = {"mass": "kg", "stiffness": "N/m", "damping": "N*s/m", "normal_load": "N",
            "coupling_stiffness": "N/m", "belt_speed": "m/s"}


def _si_value(name: str, value) -> np.ndarray:
    """An argument of `from_physical` as a float array in its SI unit (`SI_UNITS`):
    a number or array is taken as SI already; a `pint` quantity is converted.

    **Raises:** `ValidationError` naming the argument for a quantity that pint cannot
    convert to the unit, or a value that is not real numbers."""
    if hasattr(value, "magnitude") and hasattr(value, "to"):
        import pint

        try:
            value = value.to(SI_UNITS[name]).magnitude
        except pint.errors.DimensionalityError as err:
            raise ValidationError(f"{name} must be in units of {SI_UNITS[name]}: cannot "
                                  f"convert {err.units1} to it") from None
    try:
        a = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ValidationError(f"{name} must be real numbers in {SI_UNITS[name]}, got "
                              f"{value!r}") from None
    if not np.all(np.isfinite(a)):
        raise ValidationError(f"{name} must be finite, got {a.tolist()!r}")
    return a


def from_physical(*, mass, stiffness, normal_load, friction, belt_speed, damping=0.0,
                  coupling_stiffness=0.0, n_osc: int | None = None, boundary: str = "ring",
                  graph=None, reference: int = 0):
    """A chain given in SI units, made dimensionless as eqs. (4)-(6) of the paper
    with its reference oscillator's mass m, stiffness k and normal load P:

        x~ = x k / P,  t~ = t omega_n (omega_n = sqrt(k / m)),  xi_n = c_n / (2 m omega_n),
        m_n / m,  k_n / k,  P_n / P,  eta_c = k_c / k,  v~ = v / (x_0 omega_n).

    **Arguments** (keywords; numbers and arrays are read in SI units, `pint`
    quantities are converted; arrays hold one value per oscillator, or per link for
    `coupling_stiffness`):

    - `mass`: m_n, kg.
    - `stiffness`: ground stiffness k_n, N/m.
    - `normal_load`: P_n, N.
    - `friction`: the friction law with its velocities in m/s (`v0`, `v_s`, a
        table's speeds; coefficients per m/s for a viscous or polynomial term); it
        is rescaled by `AbstractFrictionLaw.scaled`.
    - `belt_speed`: v_d, m/s.
    - `damping`: viscous damping c_n, N s/m.
    - `coupling_stiffness`: k_c of each link, N/m.
    - `n_osc`, `boundary`, `graph`: the topology, as `ChainParams` takes it (n_osc
        from the longest per-oscillator array when not given).
    - `reference`: the index of the reference oscillator (0-based).

    **Returns:**

    The dimensionless `ChainParams`, with its `Scales` in `params.scales` (results
    carry them; `to_physical` converts back). Masses equal to the reference's give
    `mass=None` (the paper's chain).

    **Raises:**

    `ValidationError` naming the argument for a unit pint cannot convert, a value
    that is not finite, a non-positive mass, stiffness or load, a reference outside
    the chain, or what `ChainParams` refuses.
    """
    values = {name: _si_value(name, value) for name, value in (
        ("mass", mass), ("stiffness", stiffness), ("normal_load", normal_load),
        ("damping", damping), ("coupling_stiffness", coupling_stiffness),
        ("belt_speed", belt_speed))}
    for name in ("mass", "stiffness", "normal_load"):
        if not np.all(values[name] > 0):
            raise ValidationError(f"{name} must be > 0, got {values[name].tolist()!r}")
    if n_osc is None:
        n_osc = graph.n_osc if graph is not None else max(
            [1] + [values[n].size for n in ("mass", "stiffness", "normal_load", "damping")])
    if not (isinstance(reference, (int, np.integer)) and 0 <= reference < n_osc):
        raise ValidationError(f"reference must be an oscillator index in [0, {n_osc}), "
                              f"got {reference!r}")

    def of_reference(a):
        return float(a) if a.ndim == 0 else float(a[reference])

    scales = Scales.of(of_reference(values["mass"]), of_reference(values["stiffness"]),
                       of_reference(values["normal_load"]))
    omega = 1.0 / scales.time
    ratio = values["mass"] / scales.mass
    topology = {"graph": graph} if graph is not None else {"boundary": boundary}
    return ChainParams(n_osc=n_osc, xi=values["damping"] / (2 * scales.mass * omega),
                       eta_c=values["coupling_stiffness"] / scales.stiffness,
                       v_d=values["belt_speed"] / scales.velocity,
                       stiffness=values["stiffness"] / scales.stiffness,
                       load=values["normal_load"] / scales.force,
                       mass=None if np.all(ratio == 1.0) else ratio,
                       friction=friction.scaled(scales.velocity), scales=scales,
                       **topology)


#: How each variable of a result converts: by name, the kind of its quantity.
_KINDS = {"amplitudes": "length", "x_max": "length", "x_min": "length",
          "v_max": "velocity", "min_slip_speed": "velocity", "v_d": "velocity",
          "t": "time", "time": "time", "peak_times": "time", "period": "time",
          "omega": "frequency", "frequency": "frequency"}
_UNITS = {"length": "m", "velocity": "m s-1", "time": "s", "frequency": "Hz"}


def to_physical(ds: xr.Dataset, scales: Scales | None = None) -> xr.Dataset:
    """A result in SI units: displacements (`amplitudes`, `x_max`, `x_min`, the x
    rows of states) in m, velocities (`v_max`, `min_slip_speed`, `v_d`, the x'
    rows) in m/s, times (`t`, `peak_times`, `period`) in s and angular frequencies
    (`omega`) as frequencies in Hz, each with its CF `units`; other variables as
    they are.

    **Arguments:**

    - `ds`: a Dataset of jaxchain (dimensionless), whose attributes carry the
        scales (`Scales.record`) when its chain came from `from_physical`.
    - `scales`: the `Scales`, when `ds` does not carry them.

    **Returns:**

    A new Dataset, attribute `units` = "SI".

    **Raises:**

    `ValidationError` when neither `ds` nor `scales` gives the scales.
    """
    scales = scales if scales is not None else Scales.from_record(dict(ds.attrs))
    if scales is None:
        raise ValidationError("the result carries no scales (its chain was not made by "
                              "from_physical): pass scales=")
    factor = {"length": scales.length, "velocity": scales.velocity, "time": scales.time,
              "frequency": 1.0 / (2 * np.pi * scales.time)}
    out = ds.copy()
    for name in list(out.variables):
        var = out[name]
        kind = _KINDS.get(name)
        if var.dtype.kind not in "fiu":
            continue
        if kind is not None:
            out[name] = var * factor[kind]
            out[name].attrs = var.attrs | {"units": _UNITS[kind]}
        elif "component" in var.dims and var.sizes["component"] == 2:
            both = np.asarray([factor["length"], factor["velocity"]])
            shape = [2 if d == "component" else 1 for d in var.dims]
            out[name] = var * both.reshape(shape)
            out[name].attrs = var.attrs | {"units": "m (x), m s-1 (x')"}
    out.attrs = dict(ds.attrs) | {"units": "SI"}
    return out
