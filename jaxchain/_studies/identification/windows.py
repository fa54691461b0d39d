"""Multiple shooting over the records: each record cut into windows, each window
integrated from its own fitted initial state by the fitted model, and the
residuals of the fit (misfit to the samples, continuity between windows).

Multiple shooting for parameter estimation in ODEs: Bock (1983), "Recent advances
in parameter identification techniques for ODE", in Numerical Treatment of
Inverse Problems in Differential and Integral Equations, Birkhauser, 95-121; and
van Domselaar & Hemker (1975), Report NW 18/75, Mathematisch Centrum, Amsterdam.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int

from ..._engine.engines import AbstractEngine
from ..._checks import check_positive
from ..._errors import ValidationError
from ..._physics.params import ChainParams
from .records import Record


class Windows(eqx.Module):
    """The records cut into W windows of K samples (padded), for `jax.vmap`.

    **Fields:**

    - `times`: times from each window's start, shape (W, K + 1): its samples
        (padded by repeating the last), then the next window's start.
    - `data`: measured (x, x') of each oscillator, shape (W, K, 2, n_osc), 0
        where not measured.
    - `mask`: which entries of `data` are measured, shape (W, K, 2, n_osc).
    - `linked`: whether the window continues into the next one (the same record),
        shape (W,).
    - `record`: the record of each window, shape (W,).
    - `v_d`: the belt speed of each window, shape (W,).
    - `start`: (record, first sample) of each window (static).
    """

    times: Float[Array, "W K1"]
    data: Float[Array, "W K 2 n"]
    mask: Bool[Array, "W K 2 n"]
    linked: Bool[Array, " W"]
    record: Int[Array, " W"]
    v_d: Float[Array, " W"]
    start: tuple = eqx.field(static=True)

    @property
    def n_windows(self) -> int:
        return int(self.times.shape[0])


def cut(records: list[Record], n_osc: int, window: float) -> Windows:
    """The records cut into windows of about `window` time units (equal numbers of
    samples within a record).

    **Raises:** `ValidationError` for a window <= 0, or a record whose windows would
    hold fewer than 2 samples."""
    check_positive("window", window)
    pieces = []
    for r, rec in enumerate(records):
        duration = float(rec.t[-1] - rec.t[0])
        count = max(1, int(round(duration / window)))
        chunks = np.array_split(np.arange(rec.t.size), count)
        if min(c.size for c in chunks) < 2:
            raise ValidationError(f"{rec.source}: a window of {window} holds fewer than 2 "
                                  "samples: choose a longer window")
        for k, chunk in enumerate(chunks):
            nxt = chunks[k + 1][0] if k + 1 < count else None
            pieces.append((r, chunk, nxt))
    size = max(c.size for _, c, _ in pieces)
    times, data, mask, linked = [], [], [], []
    for r, chunk, nxt in pieces:
        rec = records[r]
        t = rec.t[chunk] - rec.t[chunk[0]]
        pad = size - chunk.size
        end = rec.t[nxt] - rec.t[chunk[0]] if nxt is not None else t[-1]
        times.append(np.concatenate([t, np.full(pad, t[-1]), [end]]))
        d = np.zeros((size, 2, n_osc))
        m = np.zeros((size, 2, n_osc), dtype=bool)
        cols = np.asarray(rec.oscillators) - 1
        d[:chunk.size, 0, cols] = rec.x[chunk]
        m[:chunk.size, 0, cols] = True
        if rec.v is not None:
            d[:chunk.size, 1, cols] = rec.v[chunk]
            m[:chunk.size, 1, cols] = True
        data.append(d)
        mask.append(m)
        linked.append(nxt is not None)
    return Windows(times=jnp.asarray(np.stack(times)), data=jnp.asarray(np.stack(data)),
                   mask=jnp.asarray(np.stack(mask)), linked=jnp.asarray(linked),
                   record=jnp.asarray([r for r, _, _ in pieces]),
                   v_d=jnp.asarray([records[r].v_d for r, _, _ in pieces]),
                   start=tuple((r, int(c[0])) for r, c, _ in pieces))


def window_flow(params: ChainParams, y0, times, engine: AbstractEngine):
    """The model's states at `times` (from 0) from `y0`, shape (len(times), 2,
    n_osc); NaN where the integration failed. Integrated by the `engine`
    (`AbstractEngine.flow`): the smoothed model (eq. (5) with tanh(v_rel/eps))
    by diffrax in forward mode, or the exact stick/slip switch model event by event,
    whose derivatives cross every switch (the event times by the implicit function
    theorem).

    **Arguments:**

    - `params`: the chain.
    - `y0`: the state at t = 0, shape (2, n_osc).
    - `times`: increasing times from 0, shape (K,).
    - `engine`: the fitted model (`IdentifyOptions.engine`), with its solver,
        tolerances and step budget; its array leaves (the smoothed engine's eps)
        are traced, so that a new eps does not recompile and derivatives with
        respect to it flow through the integration.
    """
    return engine.flow(params, y0, times)


def with_offsets(ys, windows: Windows, offsets):
    """The window states `ys` (shape (W, K + 1, 2, n_osc)) with the sensor `offsets`
    (one per record, or None) added to the displacements, not to the last column
    (the next window's start)."""
    if offsets is None:
        return ys
    shift = jnp.reshape(jnp.asarray(offsets)[windows.record], (-1, 1, 1))
    return ys.at[:, :-1, 0, :].add(shift)


def residuals(ys, windows: Windows, states, noise, weight):
    """(misfit, continuity) of the predictions `ys` (`with_offsets`): the model
    minus the measured values divided by each record's `noise` (standard
    deviation per measured column, shape (R, 2, n_osc)), 0 where not measured,
    shape (W, K, 2, n_osc); and `weight` times the jump of the state from each
    window's end to the next window's start `states`, 0 between records, shape
    (W, 2, n_osc)."""
    scale = noise[windows.record][:, None]
    misfit = jnp.where(windows.mask, (ys[:, :-1] - windows.data) / scale, 0.0)
    jump = ys[:, -1] - jnp.roll(states, -1, axis=0)
    continuity = weight * jnp.where(windows.linked[:, None, None], jump, 0.0)
    return misfit, continuity


def column_noise(windows: Windows, misfit, n_records: int) -> np.ndarray:
    """The root mean square of each record's unweighted misfit per measured column,
    shape (R, 2, n_osc); 1 where a column is not measured."""
    misfit, mask = np.asarray(misfit), np.asarray(windows.mask)
    record = np.asarray(windows.record)
    squares = np.zeros((n_records,) + misfit.shape[2:])
    counts = np.zeros_like(squares)
    np.add.at(squares, record, np.sum(np.where(mask, misfit**2, 0.0), axis=1))
    np.add.at(counts, record, np.sum(mask, axis=1))
    rms = np.sqrt(squares / np.maximum(counts, 1))
    return np.where(counts > 0, np.maximum(rms, 1e-12), 1.0)
