"""The observer interface: an initial state, an update on each chunk of a run, and a
final result. Memory is set by what an observer keeps, never by the run's t_end."""

import abc
from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float, PyTree

from ..horizon import AbstractHorizon
from ..._errors import ValidationError


class Chunk(eqx.Module):
    """What observers see of one chunk [t0, t1] of a run.

    **Fields:**

    - `t0`, `t1`: the chunk's bounds, shape ().
    - `ts`: times of its dense-output samples, shape (samples,), evenly spaced
        from t0 to t1 (both included); None in the transient, which is not sampled.
    - `ys`: the state at `ts`, shape (samples, *state_shape) (for the chain
        (samples, 2, n_osc): rows x and x'); None in the transient.
    - `log_growth`: log of the growth of the tangent vector over the chunk, for
        observers with `needs_tangent` (Benettin's method); None otherwise.
    """

    t0: Float[Array, ""]
    t1: Float[Array, ""]
    ts: Float[Array, " samples"] | None
    ys: PyTree | None
    log_growth: Float[Array, ""] | None


class AbstractObserver(eqx.Module):
    """A quantity observed while integrating. The run calls `init` once, `update`
    after each chunk (outside the step loop: an observer never slows a step), and
    `result` at the end. Failed runs get NaN (float), -1 (integer) or False
    (boolean) results: no partial answers.

    Every hook gets `args`, the `Model` the engine integrates: the chain
    (`args.params`) and the smoothing velocity of its friction (`args.eps`, 0 for
    the exact engine).

    Subclasses set `needs_tangent = True` to have a tangent vector propagated beside
    the trajectory (`Chunk.log_growth`); they then define `initial_tangent(y0)`,
    the unit vector it starts from (see `LargestLyapunov`).
    """

    needs_tangent: ClassVar[bool] = False

    @abc.abstractmethod
    def init(self, y0: PyTree, args: PyTree, options: AbstractHorizon) -> PyTree:
        """The observer's state before the first chunk; fixed shapes."""

    @abc.abstractmethod
    def update(self, state: PyTree, chunk: Chunk, args: PyTree,
               options: AbstractHorizon) -> PyTree:
        """The state after `chunk`."""

    @abc.abstractmethod
    def result(self, state: PyTree, args: PyTree, options: AbstractHorizon
               ) -> dict[str, Array]:
        """The observed quantities, by name."""

    @abc.abstractmethod
    def dims(self, options: AbstractHorizon) -> dict[str, tuple[str, ...]]:
        """The dims of each quantity of `result` (without batch dims), for xarray."""


def window_start(t_start: float | None, options: AbstractHorizon) -> float:
    """An observer's window start: `t_start`, or the start of the sampled window
    (`options.transient`) when None.

    **Raises:**

    `ValidationError` when `t_start` lies outside [transient, t_end).
    """
    if t_start is None:
        return options.transient
    if not options.transient <= t_start < options.t_end:
        raise ValidationError(f"an observer's t_start must lie in [transient = "
                              f"{options.transient:g}, t_end = {options.t_end:g}), "
                              f"got {t_start!r}")
    return float(t_start)


def _slack(t: float) -> float:
    """How far a sample may miss a window edge t and still count as on it."""
    return 1e-9 * max(1.0, abs(t))


def in_window(chunk: Chunk, start: float) -> Array:
    """Mask of the chunk's samples at or after `start`, shape (samples,)."""
    return chunk.ts >= start - _slack(start)


def in_halves(chunk: Chunk, start: float, end: float) -> Array:
    """Masks of the chunk's samples in the first and in the second half of the
    window [start, end], shape (2, samples); a sample at the middle is in both."""
    mid = 0.5 * (start + end)
    return jnp.stack([in_window(chunk, start) & (chunk.ts <= mid + _slack(mid)),
                      chunk.ts >= mid - _slack(mid)])


def observe_chunk(observers, states: tuple, chunk: Chunk, args: PyTree,
                  options: AbstractHorizon) -> tuple:
    """The observers' states after `chunk`: the one route by which both engines,
    the smoothed (`integrate`, a chunk of dense samples) and the non-smooth
    reference (`Exact.run`, one sample per located event), observe a run."""
    return tuple(o.update(s, chunk, args, options) for o, s in zip(observers, states))


def no_partial_answers(results: dict, ok) -> dict:
    """An observer's results where the run failed: NaN (float), -1 (integer) or
    False (boolean), never a partial answer."""

    def mask(value):
        value = jnp.asarray(value)
        if jnp.issubdtype(value.dtype, jnp.bool_):
            return value & ok
        if jnp.issubdtype(value.dtype, jnp.integer):
            return jnp.where(ok, value, -1)
        return jnp.where(ok, value, jnp.nan)

    return {k: mask(v) for k, v in results.items()}
