"""Sliding bifurcations of periodic orbits of the exact switch model: where a stick
phase of one oscillator shrinks to zero duration along a branch, located by the
secant method on that defining condition."""

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float

from .._errors import ValidationError
from .._physics.params import parameter_value, with_parameter
from .continuation import ContinuationProblem, PseudoArclength, _correct, _record
from .periodic_orbit import cycle_method, orbit_residual
from .._printing import values_repr

#: The fraction of the way to the secant method's root that each trial goes.
_FRACTION = 0.5
#: The secant's second orbit lies at least this fraction of the first's distance
#: from the root away from the first.
_SPREAD = 0.25
#: Trials stop when the step towards the root has halved to this fraction of the
#: way: the corrector fails that near the last orbit (or p* lies there).
_WALL = 1e-3


class SlidingPoint(eqx.Module):
    """A sliding bifurcation of a branch of periodic orbits of the exact switch
    model, located by `locate_sliding`.

    **Fields:**

    - `p`: the continued parameter there, where the stick phase's duration
        vanishes, shape () (dimensionless, eq. (6)).
    - `oscillator`: the oscillator whose stick phase vanishes (0-based).
    - `z`: the orbit (u, p) nearest to it on the side where the stick phase
        exists, shape (n + 1,).
    - `stick`: the shortest stick phase of `oscillator` on that orbit, shape ().
    - `record`: `problem.describe` of that orbit (a `PeriodicOrbit`).
    - `step`: the last change of the secant method's estimate of p (its
        resolution; inf if it did not converge), shape ().
    - `iterations`: orbits solved, the first included.
    - `converged`: whether the last change was below the tolerance.
    """

    p: Float[Array, ""]
    oscillator: int = eqx.field(static=True)
    z: Float[Array, " n+1"]
    stick: Float[Array, ""]
    record: eqx.Module
    step: Float[Array, ""]
    iterations: int = eqx.field(static=True)
    converged: bool = eqx.field(static=True)

    __repr__ = values_repr


def exact_problem(problem: ContinuationProblem) -> bool:
    """Whether `problem` continues periodic orbits whose engine has exact stick
    phases (the exact switch model's, `AbstractEngine.has_stick_phases`); False for
    any other problem."""
    residual = orbit_residual(problem)
    return residual is not None and residual.method.engine.has_stick_phases


def _phases(problem: ContinuationProblem, z) -> np.ndarray:
    method = cycle_method(problem)
    y0, period = method.orbit(z[:-1])
    return method.engine.stick_phases(problem.at(z[-1]), y0, period)


def vanishing_stick(problem: ContinuationProblem, z_stick, z_other) -> int:
    """The oscillator whose stick phase exists at the orbit `z_stick` and not at
    `z_other` (two orbits of `problem` on either side of a sliding bifurcation),
    the one with the shortest such phase; where none is missing at `z_other`, the
    oscillator with the shortest stick phase at `z_stick`."""
    here, there = _phases(problem, z_stick), _phases(problem, z_other)
    gone = np.isfinite(here) & ~np.isfinite(there)
    return int(np.argmin(np.where(gone if gone.any() else np.isfinite(here), here, np.inf)))


def _root(stick, previous: float) -> float:
    """The secant method's root of g(p) from the orbit of smallest g and, of the
    others, the one of smallest g that lies at least `_SPREAD` times the first's
    distance from the previous root away from it (or the farthest, while there is
    no root yet): trials that crowd near the last orbit that converges, where the
    corrector fails just beyond, would make the secant ill-conditioned. NaN where
    g does not fall towards a root."""
    (p1, g1, _), rest = stick[0], stick[1:]
    if not rest:
        return np.nan
    far = [q for q in rest if abs(q[0] - p1) >= _SPREAD * abs(previous - p1)]
    p2, g2, _ = far[0] if np.isfinite(previous) and far else max(rest,
                                                                 key=lambda q: abs(q[0] - p1))
    return p1 - g1 * (p1 - p2) / (g1 - g2) if g2 > g1 else np.nan


def _predict(stick, trial: float, root: float):
    """The orbit predicted at p = `trial` from the two orbits that stick nearest to
    it: linear in sqrt|p* - p| (p* = `root`), as an orbit whose stick phase
    vanishes like a square root varies; the nearest orbit itself where there is no
    root yet or the points do not lie on one side of it."""
    (p1, _, z1), (p2, _, z2) = (sorted(stick, key=lambda q: abs(q[0] - trial)) * 2)[:2]
    side = np.sign(root - np.array([p1, p2, trial]))
    if len(stick) < 2 or not np.isfinite(root) or not (side == side[0]).all() or p1 == p2:
        return z1.at[-1].set(trial)
    s1, s2, st = np.sqrt(np.abs(root - np.array([p1, p2, trial])))
    return (z1 + (st - s1) / (s2 - s1) * (z2 - z1)).at[-1].set(trial)


def _checked_start(problem: ContinuationProblem, z_stick,
                   oscillator: int | None) -> tuple:
    """`locate_sliding`'s start, checked: (z, n, d_n), the orbit `z_stick` as an
    array, the oscillator n whose stick phase vanishes (`oscillator`, or the one
    with the shortest stick phase there) and the duration d_n of that phase.
    Raises `ValidationError` as `locate_sliding` does."""
    if not exact_problem(problem):
        raise ValidationError("locate_sliding needs the ContinuationProblem of exact orbits "
                              "(cycle_problem with Shooting(Exact().for_orbits()))")
    z = jnp.asarray(z_stick, dtype=float)
    d = _phases(problem, z)
    n = int(np.argmin(np.where(np.isfinite(d), d, np.inf))) if oscillator is None else oscillator
    if not 0 <= n < d.size or not np.isfinite(d[n]):
        raise ValidationError(f"z_stick has no stick phase of oscillator {n}")
    return z, n, d[n]


def _sticking_orbits(problem: ContinuationProblem, z, d_n, n: int, seeds) -> list:
    """The orbits the secant method starts from, as (p, g, orbit), g = d^2 the
    squared duration of oscillator n's stick phase, the smallest g first: `z`
    (whose phase lasts `d_n`) and each of `seeds` that has the phase."""
    stick = [(float(z[-1]), float(d_n) ** 2, z)]  # (p, g, orbit) of orbits that stick
    for seed in seeds:
        seed = jnp.asarray(seed, dtype=float)
        d_seed = _phases(problem, seed)[n]
        if np.isfinite(d_seed) and d_seed > 0:
            stick.append((float(seed[-1]), float(d_seed) ** 2, seed))
    stick.sort(key=lambda q: q[1])
    return stick


def _secant(problem: ContinuationProblem, algorithm: PseudoArclength, stick: list, n: int,
            held, *, delta: float, xtol: float, max_iterations: int) -> tuple:
    """The trials of `locate_sliding` (see there) from the orbits `stick`
    (`_sticking_orbits`), to which each orbit found that sticks is added in
    place, the smallest g first, each corrected with p held (`held`, the
    corrector's constraint); (root, change, iterations): the last root of the
    secant method (NaN if none), its last change (inf if none) and the orbits
    solved, the first included."""
    probes = [] if len(stick) > 1 else [stick[0][0] + delta, stick[0][0] - delta]
    root = _root(stick, np.nan)
    change, fraction, iterations = np.inf, _FRACTION, 1
    while iterations < max_iterations:
        if len(stick) < 2:
            if not probes:
                break
            trial = probes.pop(0)
        elif not np.isfinite(root):  # g does not fall towards a root from here
            break
        else:  # towards the root, never onto it (d = 0 there: a degenerate orbit)
            (p1, _, _), (p2, _, _) = stick[:2]
            span = 10 * abs(p1 - p2)
            trial = p1 + fraction * float(np.clip(root - p1, -span, span))
        iterations += 1
        new, ok, _, _ = _correct(problem, algorithm, _predict(stick, trial, root), held)
        dn = _phases(problem, new)[n] if bool(ok) else np.nan
        if not (np.isfinite(dn) and dn > 0):  # beyond p*, or another orbit: step shorter
            fraction /= 2
            if fraction < _WALL:
                break
            continue
        fraction = _FRACTION
        stick.append((trial, dn**2, new))
        stick.sort(key=lambda q: q[1])  # the smallest g first: nearest the root
        estimate = _root(stick, root)
        if not np.isfinite(estimate):
            continue
        previous, root = root, estimate
        change = abs(root - previous)
        if len(stick) > 2 and change < xtol:
            break
    return root, change, iterations


def locate_sliding(problem: ContinuationProblem, z_stick,
                   algorithm: PseudoArclength = PseudoArclength(), *,
                   oscillator: int | None = None, xtol: float = 1e-9,
                   delta: float = 1e-3, max_iterations: int = 40,
                   seeds=()) -> SlidingPoint:
    """Locate the sliding bifurcation at which a stick phase of one oscillator
    vanishes, from an orbit of the exact switch model near it that has the phase.

    The defining condition is the stick phase's duration d(p) = 0. It vanishes
    like a square root, d(p)^2 ~ c (p* - p): the slip arc before the stick phase
    arrives at v_rel = 0 ever more tangentially, where the force needed to stick is
    ever nearer the static friction that ends it. So p* is a simple root of g(p) =
    d(p)^2, on the side where the orbit sticks, and is found by the secant method
    on g (superlinear; Dennis and Schnabel, *Numerical Methods for Unconstrained
    Optimization and Nonlinear Equations* (1996), Sect. 2.6) through the two
    orbits of smallest g (the second at least a quarter of the first's distance
    from the root away, so that the secant stays well conditioned). Each g(p)
    comes from the orbit solved at p: the pseudo-arclength corrector of `problem`
    with p held, from the orbit predicted linearly in sqrt|p* - p| along the two
    nearest orbits. Each trial goes half the way to the current root (d = 0
    exactly is a degenerate orbit, and the prediction's error grows towards it),
    and half as far again after a trial whose orbit does not converge or does not
    stick (beyond p*, or another orbit). It stops when two successive roots differ
    by less than `xtol`. For every friction law of jaxchain (the slip force at
    v_rel -> 0 is the static bound) p* is also where the slip arc meets v_rel = 0
    tangentially (x'' = 0 there exactly when the force needed to stick is the
    static bound): the grazing of the stick-slip orbit, such as the single
    oscillator's existence limit (`stick_slip_existence_limit`), is this point.
    di Bernardo, Budd, Champneys and Kowalczyk,
    *Piecewise-smooth Dynamical Systems* (2008), Sect. 8.5, on sliding
    bifurcations of periodic orbits.

    **Arguments:**

    - `problem`: the exact branch's `ContinuationProblem` (`cycle_problem` on the exact engine).
    - `z_stick`: a converged orbit (u, p) of the branch where the stick phase
        exists, shape (n + 1,).
    - `algorithm`: the corrector (`PseudoArclength`).
    - `oscillator`: the oscillator whose stick phase vanishes (0-based); by default
        the one with the shortest stick phase at `z_stick`.
    - `xtol`: the tolerance on successive estimates of p*.
    - `delta`: the distance from `z_stick`'s p of the first trials, which give the
        second orbit of the secant method (p + delta, then p - delta).
    - `max_iterations`: orbits solved at most.
    - `seeds`: further converged orbits (u, p) with the stick phase, each of shape
        (n + 1,), such as the branch's points before `z_stick`: the secant method
        starts from them, with no trial at +- `delta`. Near a sliding point where
        another orbit, without the stick phase, lies on the same side (the branch
        turns there), a trial predicted from `z_stick` alone can converge to that
        one.

    **Returns:**

    A `SlidingPoint`.

    **Raises:**

    `ValidationError` if `problem.residual` is not an exact shooting residual or
    `z_stick` has no stick phase (of `oscillator`).
    """
    z, n, d_n = _checked_start(problem, z_stick, oscillator)
    held = jnp.zeros(z.size).at[-1].set(1.0)  # the corrector's constraint: p as predicted
    stick = _sticking_orbits(problem, z, d_n, n, seeds)
    root, change, iterations = _secant(problem, algorithm, stick, n, held, delta=delta,
                                       xtol=xtol, max_iterations=max_iterations)
    converged = bool(change < xtol)
    p, g, z = stick[0]
    return SlidingPoint(p=jnp.asarray(root if np.isfinite(root) else p), oscillator=n, z=z,
                        stick=jnp.asarray(np.sqrt(g)), record=_record(problem, z),
                        step=jnp.asarray(change if converged else np.inf),
                        iterations=iterations, converged=converged)


class SlidingCurve(eqx.Module):
    """A two-parameter curve of sliding bifurcations (`sliding_curve`): the
    continued parameter at which one oscillator's stick phase vanishes, against a
    second parameter.

    **Fields:**

    - `other`: the second parameter's name.
    - `values`: its values, shape (m,).
    - `p`: the continued parameter at the sliding point for each, shape (m,)
        (dimensionless, eq. (6)); NaN where it was not located.
    - `z`: the orbit (u, p) nearest to each point on the side where the stick phase
        exists, shape (m, n + 1).
    - `step`: the secant method's last change of p at each (inf where it did not
        converge), shape (m,).
    - `converged`: whether each point converged, shape (m,).
    - `oscillator`: the oscillator whose stick phase vanishes (0-based).
    """

    other: str = eqx.field(static=True)
    values: Float[Array, " m"]
    p: Float[Array, " m"]
    z: Float[Array, "m n+1"]
    step: Float[Array, " m"]
    converged: Bool[Array, " m"]
    oscillator: int = eqx.field(static=True)


def _at(problem: ContinuationProblem, other: str, value: float) -> ContinuationProblem:
    """`problem` with the second parameter `other` set to `value`."""
    return eqx.tree_at(lambda q: q.params, problem,
                       with_parameter(problem.params, other, value))


def _stick_side(problem, z, oscillator: int, guess: float, side: float, margin: float,
                algorithm: PseudoArclength, tries: int = 8):
    """An orbit of `problem` (the continued parameter held) on which `oscillator`
    sticks, at `margin` from the sliding point predicted at `guess` on the stick
    side (`side`, the sign of p - p* there), corrected from `z` (an orbit of a
    neighbouring problem); the margin doubled while the orbit does not converge or
    does not stick. Returns (the orbit, the margin), or (None, margin) if none
    does."""
    held = jnp.zeros(z.size).at[-1].set(1.0)
    for _ in range(tries):
        new, ok, _, _ = _correct(problem, algorithm, z.at[-1].set(guess + side * margin), held)
        if bool(ok) and np.isfinite(_phases(problem, new)[oscillator]):
            return new, margin
        margin *= 2
    return None, margin


def _located(problem, other: str, value: float, path: list, oscillator: int, side: float,
             margin: float, algorithm: PseudoArclength, xtol: float) -> SlidingPoint | None:
    """The sliding point at `value` of `other`, predicted from the last two points of
    `path` ((value, p*, orbit) followed so far; linearly), or None where it was not
    located."""
    if len(path) < 2 or path[-1][0] == path[-2][0]:
        guess = path[-1][1]
    else:  # the line through the last two points
        (a0, p0, _), (a1, p1, _) = path[-2:]
        guess = p1 + (p1 - p0) / (a1 - a0) * (value - a1)
    here = _at(problem, other, value)
    start, used = _stick_side(here, path[-1][2], oscillator, guess, side, margin, algorithm)
    if start is None:
        return None
    found = locate_sliding(here, start, algorithm, oscillator=oscillator, xtol=xtol,
                           delta=0.5 * used)
    return found if found.converged else None


def _advance(problem, other: str, path: list, target: float, oscillator: int, side: float,
             margin: float, algorithm: PseudoArclength, xtol: float,
             halvings: int = 6) -> SlidingPoint | None:
    """Follow the sliding point from the last point of `path` to `target` of `other`,
    in steps halved where a point is not located (at most `halvings` times),
    appending each point located to `path`; the point at `target`, or None."""
    start = path[-1][0]
    h, found = target - start, None
    while found is None or path[-1][0] != target:
        value = path[-1][0] + h  # one step on, never past the target
        if abs(value - start) >= abs(target - start):
            value = target
        point = _located(problem, other, value, path, oscillator, side, margin, algorithm, xtol)
        if point is None:
            h /= 2
            if abs(h) < abs(target - start) / 2**halvings or h == 0:
                return None
            continue
        path.append((value, float(point.p), point.z))
        found = point
    return found


def sliding_curve(problem: ContinuationProblem, point: SlidingPoint, other: str, values,
                  algorithm: PseudoArclength = PseudoArclength(), *, xtol: float = 1e-9,
                  margin: float = 1e-4) -> SlidingCurve:
    """The sliding bifurcation of a branch of exact periodic orbits followed in a
    second parameter: a two-parameter curve of sliding points (for the single
    oscillator the curve of its existence limit, `grazing_curve`; for a localized
    state of a chain the edge of its stick-slip cycle against xi, mu_st, ...), by
    natural-parameter continuation (Seydel, *Practical Bifurcation and Stability
    Analysis*, 3rd ed. (2010), Sect. 4.1; Kowalczyk and Piiroinen (2008), Physica
    D 237, 1053, follow sliding bifurcations of friction oscillators in two
    parameters). Outwards from the value nearest to that of `problem.params`, at
    each value: the sliding point predicted from the previous two (linearly), an
    orbit on its stick side at `margin` from it (the corrector with the continued
    parameter held, from the previous point's orbit; the margin doubled until the
    orbit sticks), then `locate_sliding` from there on the defining condition
    d^2 = 0. Where that fails, the step in `other` is halved (up to six times),
    through intermediate values that are not returned.

    **Arguments:**

    - `problem`: the exact branch's `ContinuationProblem` (`cycle_problem` on the exact engine)
        at the first point's parameters.
    - `point`: a converged `SlidingPoint` of that problem (`locate_sliding`).
    - `other`: the second parameter, a name that `with_parameter` takes.
    - `values`: its values, shape (m,), increasing.
    - `algorithm`: the corrector (`PseudoArclength`).
    - `xtol`: `locate_sliding`'s tolerance on p.
    - `margin`: the first distance in p from the predicted sliding point of the
        orbit each location starts from.

    **Returns:**

    A `SlidingCurve`. Past a value whose point was not located, the points on that
    side are NaN.

    **Raises:**

    `ValidationError` (a `ValueError`) for a `point` that did not converge, values
    that are not increasing, a `margin` that is not > 0, or a problem that is not
    exact (`locate_sliding`).
    """
    if not point.converged:
        raise ValidationError("sliding_curve starts from a converged SlidingPoint")
    values = np.asarray(values, dtype=float)
    if values.ndim != 1 or values.size == 0 or np.any(np.diff(values) <= 0):
        raise ValidationError("values must be a 1-D array of increasing values")
    if not (np.isfinite(margin) and margin > 0):
        raise ValidationError(f"margin must be a finite number > 0, got {margin!r}")
    first = float(parameter_value(problem.params, other))
    at = int(np.argmin(np.abs(values - first)))
    side = float(np.sign(float(point.z[-1]) - float(point.p))) or -1.0
    p = np.full(values.size, np.nan)
    step = np.full(values.size, np.inf)
    zs = np.full((values.size, point.z.size), np.nan)
    for order in (range(at, values.size), range(at - 1, -1, -1)):
        path = [(first, float(point.p), point.z)]  # (value, p*, orbit) followed so far
        for k in order:
            found = _advance(problem, other, path, float(values[k]), point.oscillator, side,
                             margin, algorithm, xtol)
            if found is None:
                break
            p[k], step[k], zs[k] = float(found.p), float(found.step), np.asarray(found.z)
    return SlidingCurve(other=other, values=jnp.asarray(values), p=jnp.asarray(p),
                        z=jnp.asarray(zs), step=jnp.asarray(step),
                        converged=jnp.asarray(np.isfinite(p)), oscillator=point.oscillator)
