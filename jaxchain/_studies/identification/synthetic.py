"""Records made by the event-driven non-smooth reference, with known parameters and
optional measurement noise, and records written as CSV files: the test bench of the
identification, and a way to try it before a rig is measured."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from ..._errors import ValidationError
from ..._engine.exact.options import NonsmoothOptions
from ..._engine.exact.solve import nonsmooth_trajectory
from ..._physics.params import ChainParams, with_parameter
from ..._sweeps.atomic import write_text
from .records import Record


def reference_record(params: ChainParams, v_d: float, t_end: float, dt: float, *,
                     oscillators=(1,), velocities: bool = False, noise: float = 0.0,
                     offset: float = 0.0, seed: int = 0, y0=None,
                     options: NonsmoothOptions = NonsmoothOptions.reference()) -> Record:
    """A record of the chain at belt speed `v_d`, made by the non-smooth reference
    (`nonsmooth_trajectory`: the exact switch model, no smoothing), sampled every
    `dt` over [0, t_end], with Gaussian noise.

    **Arguments:**

    - `params`: the chain with the true parameters (nothing is smoothed).
    - `v_d`, `t_end`, `dt`: belt speed, duration and sample interval
        (dimensionless, eq. (4)).
    - `oscillators`: the measured oscillators, numbered from 1.
    - `velocities`: also record their velocities.
    - `noise`: the noise's standard deviation relative to each column's
        amplitude (half of peak to peak): 0.005 is 0.5 % of the amplitude.
    - `offset`: a sensor offset added to every measured displacement.
    - `seed`: the seed of the noise (`numpy.random.default_rng`).
    - `y0`: the state at t = 0, shape (2, n_osc); default at rest, x = 0, x' = 0.
    - `options`: the reference's tolerances.

    **Returns:** a `Record` (source "reference v_d=...").

    **Raises:** `ValidationError` for an oscillator outside the chain, dt or
    t_end <= 0, or noise < 0.
    """
    if not (dt > 0 and t_end > dt):
        raise ValidationError(f"dt and t_end must satisfy 0 < dt < t_end, got {dt!r}, "
                              f"{t_end!r}")
    if not noise >= 0:
        raise ValidationError(f"noise must be >= 0, got {noise!r}")
    cols = np.asarray(oscillators, dtype=int) - 1
    if cols.size == 0 or cols.min() < 0 or cols.max() >= params.n_osc:
        raise ValidationError(f"oscillators must be numbers 1..{params.n_osc}, got "
                              f"{tuple(oscillators)!r}")
    ts = np.arange(int(np.floor(t_end / dt + 1e-9)) + 1) * dt
    y0 = np.zeros((2, params.n_osc)) if y0 is None else np.asarray(y0, dtype=float)
    ys = np.asarray(nonsmooth_trajectory(with_parameter(params, "v_d", v_d), y0, ts,
                                         options))
    rng = np.random.default_rng(seed)

    def measured(values):
        amplitude = 0.5 * (values.max(axis=0) - values.min(axis=0))
        return values + noise * amplitude * rng.standard_normal(values.shape)

    x = measured(ys[:, 0, cols]) + offset
    v = measured(ys[:, 1, cols]) if velocities else None
    return Record(t=ts, x=x, oscillators=tuple(int(c) + 1 for c in cols), v=v,
                  v_d=float(v_d), source=f"reference v_d={v_d:g}")


def write_record(record: Record, path: str | Path, scales=None) -> Path:
    """Write a record as the CSV file `read_record` reads (columns t, x<n>, v<n>,
    v_d), in SI units with the chain's `scales` if given, to a temporary name
    renamed into place.

    **Returns:** the path written."""
    t, x, v, v_d = record.t, record.x, record.v, np.full(record.t.shape, record.v_d)
    if scales is not None:
        t, x, v_d = t * scales.time, x * scales.length, v_d * scales.velocity
        v = None if v is None else v * scales.velocity
    columns = {"t": t}
    for j, n in enumerate(record.oscillators):
        columns[f"x{n}"] = x[:, j]
    if v is not None:
        for j, n in enumerate(record.oscillators):
            columns[f"v{n}"] = v[:, j]
    columns["v_d"] = v_d
    text = io.StringIO()
    text.write(",".join(columns) + "\n")
    np.savetxt(text, np.column_stack(list(columns.values())), delimiter=",", fmt="%.17g")
    return write_text(path, text.getvalue())
