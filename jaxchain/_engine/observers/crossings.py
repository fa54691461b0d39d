"""Events found in the dense samples: peaks of x_n (x_n' = 0 with x_n'' < 0), their
times, and the Poincare section of the chain at the peaks of a reference oscillator.
Each keeps the last `capacity` events in a ring buffer: memory is set by the
capacity, never by t_end."""

import math

import equinox as eqx
import jax
import jax.numpy as jnp

from .base import AbstractObserver, in_window, window_start


def downward_crossings(ts, x, v, seen):
    """Peaks of x: where x' = v goes from > 0 to <= 0 between consecutive samples,
    and when.

    **Arguments:**

    - `ts`: sample times, shape (samples,), evenly spaced.
    - `x`, `v`: the signal and its derivative, shape (samples, *channels).
    - `seen`: mask of the samples inside the window, shape (samples,).

    **Returns:**

    (mask, s): both of shape (samples - 1, *channels); `mask` marks the intervals
    holding a peak, `s` in [0, 1] its position within the interval: the root of
    the derivative of the cubic Hermite polynomial through (x, v) at both ends,
    by two Newton steps from the linear interpolation of v (error O(h^3), h the
    sample spacing).
    """
    h = ts[1] - ts[0]
    x0, x1, v0, v1 = x[:-1], x[1:], v[:-1], v[1:]
    window = (seen[:-1] & seen[1:]).reshape(-1, *(1,) * (v.ndim - 1))
    mask = (v0 > 0) & (v1 <= 0) & window
    s = jnp.clip(v0 / jnp.where(mask, v0 - v1, 1.0), 0.0, 1.0)
    # Newton on p'(s), p the Hermite cubic of the interval: h p''(s) = 2 a s + b
    a = 6 * (x0 - x1) + 3 * h * (v0 + v1)
    b = -6 * (x0 - x1) - h * (4 * v0 + 2 * v1)
    for _ in range(2):
        slope = (2 * a * s + b) / h
        s = jnp.clip(s - hermite_velocity(x0, x1, v0, v1, h, s)
                     / jnp.where(slope < 0, slope, -1.0), 0.0, 1.0)
    return mask, s


def hermite_position(x0, x1, v0, v1, h, s):
    """x at fraction s of an interval of length h, by the cubic Hermite polynomial
    through (x0, v0) and (x1, v1), v = x' (error O(h^4))."""
    s2, s3 = s * s, s * s * s
    return ((2 * s3 - 3 * s2 + 1) * x0 + (s3 - 2 * s2 + s) * h * v0
            + (-2 * s3 + 3 * s2) * x1 + (s3 - s2) * h * v1)


def hermite_velocity(x0, x1, v0, v1, h, s):
    """x' at fraction s of the interval: the derivative of `hermite_position`
    (error O(h^3))."""
    d = x0 - x1
    return ((6 * d + 3 * h * (v0 + v1)) * s * s - (6 * d + h * (4 * v0 + 2 * v1)) * s
            + h * v0) / h


def append(buffer, count, values, mask):
    """Append the `values` picked by `mask` (in order) to a ring buffer.

    **Arguments:**

    - `buffer`: shape (capacity, *shape); `count`: events appended so far, shape ().
    - `values`: candidates, shape (k, *shape); `mask`: which are events, shape (k,).

    **Returns:**

    (buffer, count): slot r % capacity holds event r; the latest events win.
    Gathers and selects only (no scatter), so the compiled loop stays small.
    """
    capacity = buffer.shape[0]
    order = jnp.argsort(~mask, stable=True)
    new, n_new = values[order], jnp.sum(mask)
    end = count + n_new
    slot = jnp.arange(capacity)
    rank = end - 1 - jnp.mod(end - 1 - slot, capacity)
    take = (rank >= count).reshape(-1, *(1,) * (buffer.ndim - 1))
    src = jnp.clip(rank - count, 0, values.shape[0] - 1)
    return jnp.where(take, new[src], buffer), end


def _ordered(buffer, count):
    """The ring buffer's events, oldest first; unfilled slots stay NaN."""
    capacity = buffer.shape[0]
    return jnp.roll(buffer, -jnp.where(count > capacity, jnp.mod(count, capacity), 0),
                    axis=0)


def _default_capacity(start: float, options) -> int:
    """Room for two events per natural period 2 pi of the single oscillator over
    [start, t_end]: every peak of a chain whose frequencies are near 1."""
    return math.ceil((options.t_end - start) / math.pi) + 2


class PeakTimes(AbstractObserver):
    """Times of the peaks of chosen oscillators (x_n' = 0 with x_n'' < 0), from
    which the paper's time delays phi_i = tau_peak,i - tau_peak,ref are taken
    (`time_delays`).

    **Arguments:**

    - `oscillators`: 0-based indices of the oscillators to observe; all if None.
    - `t_start`: start of the window, `options.transient` by default.
    - `capacity`: peaks kept per oscillator (the last ones); by default two per
        natural period 2 pi over the window.

    **Results:**

    - `peak_times`: shape (n_peak_osc, capacity), oldest first, NaN where unused.
    - `n_peaks`: peaks found per oscillator, shape (n_peak_osc,); more than the
        capacity means the earliest were dropped.

    Peak times are interpolated between samples (`downward_crossings`), to
    a few 1e-6 at the default sample_dt of 0.05 (and the solver's dense output).
    """

    oscillators: tuple[int, ...] | None = eqx.field(static=True, default=None)
    t_start: float | None = eqx.field(static=True, default=None)
    capacity: int | None = eqx.field(static=True, default=None)

    def _size(self, options):
        start = window_start(self.t_start, options)
        return self.capacity or _default_capacity(start, options)

    def _pick(self, ys):
        x, v = ys[:, 0], ys[:, 1]
        if self.oscillators is None:
            return x, v
        index = jnp.asarray(self.oscillators)
        return x[:, index], v[:, index]

    def init(self, y0, args, options):
        m = y0.shape[-1] if self.oscillators is None else len(self.oscillators)
        return (jnp.full((m, self._size(options)), jnp.nan),
                jnp.zeros((m,), dtype=int))

    def update(self, state, chunk, args, options):
        if chunk.ts is None:
            return state
        x, v = self._pick(chunk.ys)
        mask, s = downward_crossings(chunk.ts, x, v, in_window(chunk, window_start(
            self.t_start, options)))
        times = chunk.ts[:-1, None] + s * (chunk.ts[1] - chunk.ts[0])
        return jax.vmap(append, in_axes=(0, 0, 1, 1))(*state, times, mask)

    def result(self, state, args, options):
        buffer, count = state
        return {"peak_times": jax.vmap(_ordered)(buffer, count), "n_peaks": count}

    def dims(self, options):
        return {"peak_times": ("peak_osc", "peak"), "n_peaks": ("peak_osc",)}


class PoincareSection(AbstractObserver):
    """The state of the whole chain at each peak of a reference oscillator: the
    Poincare section x_ref' = 0 with x_ref'' < 0.

    **Arguments:**

    - `ref`: 0-based index of the reference oscillator; N//2 (oscillator 11 of 20,
        the paper's reference) if None.
    - `t_start`: start of the window, `options.transient` by default.
    - `capacity`: section points kept (the last ones); by default two per natural
        period over the window.

    **Results:**

    - `section_times`: shape (capacity,), oldest first, NaN where unused.
    - `section_states`: shape (capacity, 2, n_osc): x by cubic Hermite
        interpolation between samples, x' by its derivative.
    - `n_section`: section points found, shape ().
    """

    ref: int | None = eqx.field(static=True, default=None)
    t_start: float | None = eqx.field(static=True, default=None)
    capacity: int | None = eqx.field(static=True, default=None)

    def init(self, y0, args, options):
        size = self.capacity or _default_capacity(window_start(self.t_start, options),
                                                  options)
        return (jnp.full((size,), jnp.nan), jnp.full((size, *y0.shape), jnp.nan),
                jnp.array(0))

    def update(self, state, chunk, args, options):
        if chunk.ts is None:
            return state
        times, states, count = state
        x, v = chunk.ys[:, 0], chunk.ys[:, 1]
        ref = x.shape[-1] // 2 if self.ref is None else self.ref
        mask, s = downward_crossings(chunk.ts, x[:, ref], v[:, ref], in_window(
            chunk, window_start(self.t_start, options)))
        h = chunk.ts[1] - chunk.ts[0]
        at = s[:, None]
        xs = hermite_position(x[:-1], x[1:], v[:-1], v[1:], h, at)
        vs = hermite_velocity(x[:-1], x[1:], v[:-1], v[1:], h, at)
        times, _ = append(times, count, chunk.ts[:-1] + s * h, mask)
        states, count = append(states, count, jnp.stack([xs, vs], axis=1), mask)
        return times, states, count

    def result(self, state, args, options):
        times, states, count = state
        return {"section_times": _ordered(times, count),
                "section_states": _ordered(states, count), "n_section": count}

    def dims(self, options):
        return {"section_times": ("section",),
                "section_states": ("section", "component", "osc"), "n_section": ()}
