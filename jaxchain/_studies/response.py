"""The frequency-response curve of a forced chain: its periodic orbits followed in the
forcing frequency by pseudo-arclength continuation, with their stability and folds,
as a Dataset."""

import dataclasses
import time

import numpy as np

from .._bifurcation.continuation import ContinuationOptions, PseudoArclength, continuation
from .._bifurcation.orbit_method import AbstractOrbitMethod
from .._bifurcation.periodic_orbit import cycle_problem, periodic_orbit
from .._errors import ValidationError
from .._physics.params import ChainParams
from .._physics.record import chain_record

#: The continued parameter: the forcing frequency Omega.
FREQUENCY = "forcing.frequency"


def frequency_response(params: ChainParams, method: AbstractOrbitMethod, frequency_end: float,
                       options: ContinuationOptions = ContinuationOptions(ds=0.05, ds_max=0.5,
                                                                          max_points=300), *,
                       progress: bool = False):
    """The frequency-response curve of the forced chain `params` from its forcing
    frequency to `frequency_end`: the forced orbit at the start (from the chain at
    rest in its steady-sliding position, or at x = 0 without a belt), then
    pseudo-arclength continuation in Omega (`cycle_problem` with `where =
    "forcing.frequency"`), which passes the curve's folds.

    **Arguments:**

    - `params`: a forced chain (`ChainParams.forcing`).
    - `method`: the orbit method (`HarmonicBalance(...)` or `Shooting(...)`).
    - `frequency_end`: the other end of the frequency range (> 0, not the start).
    - `options`: the continuation's steps and budget; its direction and parameter
        bounds are set from the range.
    - `progress`: a progress bar, one tick per point.

    **Returns:**

    An `xarray.Dataset` over `point` (the converged points in order along the
    curve) and `osc` (1..N): `frequency` (Omega), `amplitudes` (point, osc; half of
    peak-to-peak over the method's samples), `max_amplitude` (the largest over the
    chain) and `stable`; attributes: the chain (`chain_record`, without the
    frequency), the method's name and settings, the frequencies of the folds (`fold_frequencies`,
    where dOmega/ds changes sign), the continuation's stop and the wall time.
    Dimensionless (eqs. (4)-(6)).

    **Raises:**

    `ValidationError` for an unforced chain or a bad frequency range;
    `RuntimeError` where the start orbit does not converge.
    """
    import xarray as xr

    if params.forcing is None:
        raise ValidationError("frequency_response needs a forced chain: give "
                              "ChainParams(forcing=jaxchain.Forcing(...))")
    start_frequency = float(params.forcing.frequency)
    if not (np.isfinite(frequency_end) and frequency_end > 0
            and frequency_end != start_frequency):
        raise ValidationError(f"frequency_end must be a frequency > 0 other than the start "
                              f"{start_frequency:g}, got {frequency_end!r}")
    began = time.perf_counter()
    rest = method.engine.steady_sliding(params) if params.v_d > 0 else np.zeros((2, params.n_osc))
    orbit = periodic_orbit(params, (rest, float(params.forcing.period)), method)
    low, high = sorted((start_frequency, frequency_end))
    options = _bounded(options, low, high, 1 if frequency_end > start_frequency else -1)
    branch = continuation(cycle_problem(orbit, method, where=FREQUENCY), PseudoArclength(),
                          options, progress=progress)
    ok = np.asarray(branch.converged)
    records = branch.records
    amplitudes = np.asarray(records.amplitudes)
    attrs = {k: v for k, v in chain_record(params).items() if k != "force_frequency"}
    attrs |= method_settings(method) | {"stop": branch.stop.name,
              "fold_frequencies": [float(np.asarray(branch.p)[ok][i]) for i in branch.folds],
              "wall_time_s": time.perf_counter() - began,
              "units": "dimensionless, eqs. (4)-(6) of the paper"}
    return xr.Dataset(
        {"amplitudes": (("point", "osc"), amplitudes),
         "max_amplitude": ("point", amplitudes.max(axis=1)),
         "stable": ("point", np.asarray(records.stable))},
        coords={"frequency": ("point", np.asarray(branch.p)[ok]),
                "point": np.arange(int(ok.sum())), "osc": np.arange(1, params.n_osc + 1)},
        attrs=attrs)


def method_settings(method: AbstractOrbitMethod) -> dict:
    """The orbit method's name and settings (`method_harmonics`, `method_eps`, ...)
    and its engine's (`engine_eps`, `engine_rtol`, ...: `AbstractEngine.attributes`),
    for a result's attributes."""
    from .._sweeps.datasets import field_values

    engine = getattr(method, "engine", None)
    return ({"method": type(method).__name__} | field_values(method, "method_")
            | {k if k == "engine" else f"engine_{k}": v
               for k, v in (engine.attributes() if engine else {}).items()})


def _bounded(options: ContinuationOptions, low: float, high: float, direction: int
             ) -> ContinuationOptions:
    return dataclasses.replace(options, p_min=low, p_max=high, direction=direction)
