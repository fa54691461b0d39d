"""The classes of a chain's final states, and their probabilities with Wilson
confidence intervals."""

import math

import numpy as np
from jaxtyping import Bool, Float, Int

from ..._engine.checks import real_array
from ..._physics.chain import Graph, as_graph
from ..._errors import ValidationError
from ..._analysis.states import FAILED, STEADY_SLIDING, STICK_SLIP
from ..._engine.status import Status

#: The 97.5 % quantile of the standard normal: a 95 % two-sided interval.
Z95 = 1.959963984540054


def halc_clusters(on_halc: Bool[np.ndarray, "*batch n_osc"],
                  boundary: str | Graph = "ring") -> Int[np.ndarray, "*batch"]:
    """The number of separate groups of adjacent HALC oscillators: 0 at steady
    sliding, 1 for one localized group (or the whole chain), more for several.

    **Arguments:**

    - `on_halc`: whether each oscillator is on the HALC, shape (..., n_osc).
    - `boundary`: the chain's boundary (`BOUNDARIES`): on the ring a group may run
        across the closure (oscillators N and 1 are neighbours); on an open chain
        it may not. Or the chain's `Graph`: groups connected by its links
        (`Graph.clusters`).

    **Returns:**

    Shape (...): the groups, the connected components of the HALC oscillators in
    the chain's `Graph` (`Graph.clusters`, scipy's `connected_components`).
    """
    on = np.asarray(on_halc, dtype=bool)
    return as_graph(boundary, on.shape[-1]).clusters(on)


def class_names(n_osc: int) -> list[str]:
    """The classes by n_HALC, in the vocabulary of `state_class`: "steady sliding"
    and "stick-slip" for one oscillator; "steady sliding" (n_HALC = 0) and
    "n_HALC = k", k = 1..N (localized states, and the stick-slip of the whole
    chain at k = N), for a chain; then "failed" (a run that did not finish)."""
    if n_osc == 1:
        return [STEADY_SLIDING, STICK_SLIP, FAILED]
    return [STEADY_SLIDING] + [f"n_HALC = {k}" for k in range(1, n_osc + 1)] + [FAILED]


def class_index(n_halc: Int[np.ndarray, "*batch"], status: Int[np.ndarray, "*batch"],
                n_osc: int) -> Int[np.ndarray, "*batch"]:
    """The index into `class_names(n_osc)` of each run: n_HALC, or the last
    ("failed") where the status is not 0."""
    n_halc = np.asarray(n_halc)
    return np.where(np.asarray(status) == Status.ok, n_halc, n_osc + 1)


def wilson_interval(k: Int[np.ndarray, "*shape"], n: int | Int[np.ndarray, "*shape"],
                    z: float = Z95) -> tuple[Float[np.ndarray, "*shape"],
                                             Float[np.ndarray, "*shape"]]:
    """The Wilson score interval of a binomial proportion k/n (Wilson, J. Am. Stat.
    Assoc. 22, 209-212 (1927)): the p with |k/n - p| <= z sqrt(p (1 - p) / n).
    Unlike the normal approximation it stays in [0, 1] and does not collapse to a
    point at k = 0 or k = n.

    **Arguments:**

    - `k`: successes, whole numbers with 0 <= k <= n.
    - `n`: trials, whole numbers >= 1, of a shape that broadcasts with `k`.
    - `z`: the normal quantile, a finite number > 0 (95 %: `Z95`).

    **Returns:**

    (low, high), of the broadcast shape of k and n.

    **Raises:**

    `ValidationError` naming `k`, `n` or `z` for counts that are not finite whole
    numbers, n < 1, k < 0 or k > n, shapes that do not broadcast, or a `z` that is
    not a finite number > 0; `TypeError` for values that are not real numbers.
    """
    k, n = _whole_numbers(k, "k"), _whole_numbers(n, "n")
    if np.any(n < 1):
        raise ValidationError(f"n must be a number of trials >= 1, got {n[n < 1].flat[0]:g}")
    try:
        k, n = np.broadcast_arrays(k, n)
    except ValueError:
        raise ValidationError(f"k and n must have shapes that broadcast, got {k.shape} "
                              f"and {n.shape}") from None
    outside = (k < 0) | (k > n)
    if np.any(outside):
        raise ValidationError(f"k must lie in [0, n], got k = {k[outside].flat[0]:g} with "
                              f"n = {n[outside].flat[0]:g}")
    if isinstance(z, bool) or not isinstance(z, (int, float, np.integer, np.floating)) \
            or not (math.isfinite(z) and z > 0):
        raise ValidationError(f"z must be a finite number > 0, got {z!r}")
    p = k / n
    denom = 1 + z**2 / n
    centre = (p + z**2 / (2 * n)) / denom
    half = z * np.sqrt(p * (1 - p) / n + z**2 / (4 * n**2)) / denom
    # At k = 0 and k = n the bounds are exactly 0 and 1 (centre = half there).
    low = np.where(k == 0, 0.0, np.clip(centre - half, 0.0, 1.0))
    high = np.where(k == n, 1.0, np.clip(centre + half, 0.0, 1.0))
    return low, high


def _whole_numbers(value, name: str) -> np.ndarray:
    """`value` as a float64 array of whole numbers.

    **Raises:**

    `TypeError` (`real_array`) for values that are not real numbers;
    `ValidationError` naming `name` for a value that is not finite or not whole.
    """
    a = real_array(value, name)
    bad = ~np.isfinite(a) | (a != np.round(a))
    if np.any(bad):
        raise ValidationError(f"{name} must be whole numbers (counts), got "
                              f"{float(a[bad].flat[0])!r}")
    return a
