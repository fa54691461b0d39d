"""Bifurcations of periodic orbits detected on a continued branch, classified by the
Floquet multiplier that crosses the unit circle, and located by bisection along
the branch."""

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Complex, Float

from .continuation import Branch, ContinuationProblem, PseudoArclength, _correct, _record, \
    _tangent
from .._errors import ValidationError
from .._engine.status import Status
from .sliding import SlidingPoint, _phases, exact_problem, locate_sliding, vanishing_stick
from .._printing import values_repr

#: The kinds of codimension-one bifurcation of limit cycles (Kuznetsov, *Elements of
#: Applied Bifurcation Theory*, 3rd ed. (2004), Sect. 5.4), by their critical
#: multiplier: +1 with a turning point in p (fold of limit cycles), +1 without one
#: (branch point: a symmetry-breaking pitchfork or transcritical point, where another
#: branch crosses), -1 (period doubling), a complex pair (Neimark-Sacker, torus); and
#: "Hopf", where the cycle's amplitude vanishes on steady sliding (Sect. 3.5).
BIFURCATION_KINDS = ("fold", "branch point", "period doubling", "Neimark-Sacker", "sliding",
                     "grazing", "multiplier jump", "Hopf")

#: A turning point in p whose located orbit has less than this fraction of the energy
#: of the converged orbits either side (an amplitude below 1 % of theirs) is a Hopf
#: point: the branch passes through steady sliding, where its amplitude changes sign
#: and p, even in the amplitude, turns.
HOPF_ENERGY = 1e-4

#: A change of stability whose critical multiplier still jumps by more than this
#: across the bisection's last interval is discontinuity-induced, not a crossing.
JUMP = 1e-2


class BifurcationPoint(eqx.Module):
    """A bifurcation located on a branch of periodic orbits.

    **Fields:**

    - `kind`: one of `BIFURCATION_KINDS`.
    - `p`: the continued parameter there (dimensionless, eq. (6)).
    - `z`: the solution (u, p) there, shape (n + 1,); at a sliding bifurcation the
        orbit nearest to it on the side of the stick phase (`locate_sliding`), and
        where the corrector fails around the point (a branch point) the converged
        trial nearest to it.
    - `multiplier`: the critical Floquet multiplier there (complex; modulus 1 up to
        the bisection's resolution).
    - `record`: `problem.describe` there (a `PeriodicOrbit` for limit cycles).
    - `after`: the index of the converged point of the branch after which it lies.
    - `width`: the arclength of the last bisection interval (the location's
        resolution along the branch); at a sliding bifurcation the secant method's
        last change of p (`SlidingPoint.step`).
    """

    kind: str = eqx.field(static=True)
    p: Float[Array, ""]
    z: Float[Array, " n+1"]
    multiplier: Complex[Array, ""]
    record: eqx.Module
    after: int = eqx.field(static=True)
    width: float = eqx.field(static=True)

    __repr__ = values_repr


def _critical(record) -> tuple[float, complex]:
    """(largest non-trivial |multiplier| - 1, that multiplier) of a `PeriodicOrbit`."""
    m = complex(np.asarray(record.critical_multiplier))
    return abs(m) - 1.0, m


def _bisect(test, s_hi: float, steps: int, f_hi: float):
    """Bisection on s in [0, s_hi] for a sign change of test(s), test(0) and
    f_hi (the test function at the next point of the branch) of opposite signs.
    test(s) gives (value, corrected point) or None where the corrector fails.
    Where it fails at the midpoint, the points at a quarter and an eighth of the
    interval from either end are tried, nearest the middle first; where they all
    fail, the bisection stops: around a branch point [G_u, G_p] is nearly singular
    and the corrector fails on an interval about it (2e-3 in v_d on the two-site
    branch of the ring of 20), which no bisection step can enter.
    Returns (s, width of the last interval, the corrected point of the last
    successful trial nearest the change, the last corrected points on either side
    of it, (f, z) or None, and whether it stopped at the corrector's failures), or
    (None, 0, None, None, False) when the ends have no sign change."""
    lo, hi = 0.0, s_hi
    first = test(lo)
    if first is None or np.sign(first[0]) == np.sign(f_hi):
        return None, 0.0, None, None, False
    f_lo, best = first
    sides = [first, None]
    for _ in range(steps):
        for fraction in (0.5, 0.25, 0.75, 0.125, 0.875):
            mid = lo + fraction * (hi - lo)
            trial = test(mid)
            if trial is not None:
                break
        else:
            return 0.5 * (lo + hi), hi - lo, best, sides, True
        best = trial[1]
        if np.sign(trial[0]) == np.sign(f_lo):
            lo, sides[0] = mid, trial
        else:
            hi, sides[1] = mid, trial
    return 0.5 * (lo + hi), hi - lo, best, sides, False


def _discontinuity(problem: ContinuationProblem, sides) -> tuple[str, list[int] | None]:
    """The kind of a change of stability across which the critical multiplier jumps
    (a discontinuity-induced bifurcation; di Bernardo, Budd, Champneys and Kowalczyk,
    *Piecewise-smooth Dynamical Systems* (2008), ch. 8; Leine and Nijmeijer (2004),
    ch. 8): on the exact model "sliding" where the number of zero multipliers (of
    stick phases) changes, a stick phase appearing or vanishing, else "grazing"; on
    the smoothed model, which has no switches, "multiplier jump" (too steep for the
    bisection to resolve at its eps). Returns (the kind, the count of zero
    multipliers on each side, or None on the smoothed model)."""
    records = [_record(problem, z) for _, z in sides]
    if not hasattr(records[0], "zero_multipliers"):
        return "multiplier jump", None
    zeros = [int(r.zero_multipliers) for r in records]
    return ("sliding" if zeros[0] != zeros[1] else "grazing"), zeros


def _sliding(problem: ContinuationProblem, algorithm: PseudoArclength, sides,
             zeros: list[int]) -> SlidingPoint | None:
    """The sliding bifurcation between the two sides of a change of stability
    (`_discontinuity`), located by `locate_sliding` from the side whose orbit has
    the extra stick phase (more zero multipliers, `zeros`); None where that orbit
    shows no complete stick phase to follow (the bisection's point then stays)."""
    stick, other = sides[int(np.argmax(zeros))][1], sides[int(np.argmin(zeros))][1]
    try:
        return locate_sliding(problem, stick, algorithm,
                              oscillator=vanishing_stick(problem, stick, other))
    except ValidationError:
        return None


def _bisection_test(problem: ContinuationProblem, algorithm: PseudoArclength, branch: Branch,
                    zs, tangents, i: int, fold: bool) -> tuple:
    """(test, f_hi): the test function of `_bisect` between the converged points i
    and i + 1 (the orbit z_i + s t_i corrected onto the branch, and there dp/ds at
    a fold, else |mu| - 1 of the critical multiplier mu; None where the corrector
    fails), and its value at point i + 1."""
    z0, t0 = zs[i], tangents[i]

    def corrected(s):
        new, good, _, _ = _correct(problem, algorithm, z0 + s * t0, t0)
        return new if bool(good) else None

    def test(s):
        z = corrected(s)
        if z is None:
            return None
        return (float(_tangent(problem, z, t0)[0][-1]) if fold
                else _critical(_record(problem, z))[0]), z

    if fold:
        f_hi = float(tangents[i + 1, -1])
    else:
        f_hi = float(np.abs(np.asarray(branch.records.critical_multiplier)[i + 1]) - 1)
    return test, f_hi


def _locate_change(problem: ContinuationProblem, algorithm: PseudoArclength, branch: Branch,
                   zs, tangents, i: int, fold: bool, steps: int) -> BifurcationPoint | None:
    """The fold (`fold`) or change of stability between the converged points i and
    i + 1 of `branch` (`zs`, `tangents`: theirs), located by bisection (`_bisect`,
    `steps` steps) and classified (`_classified`); None where the test function
    shows no sign change there."""
    test, f_hi = _bisection_test(problem, algorithm, branch, zs, tangents, i, fold)
    _, width, z, sides, stopped = _bisect(test, float(tangents[i] @ (zs[i + 1] - zs[i])),
                                          steps, f_hi)
    if z is None:
        return None
    if sides[1] is None:  # no trial beyond the change: the branch's next point
        sides[1] = (f_hi, zs[i + 1])
    return _classified(problem, algorithm, branch, i, fold, z, sides, stopped, width)


def _classified(problem: ContinuationProblem, algorithm: PseudoArclength, branch: Branch,
                i: int, fold: bool, z, sides, stopped: bool, width: float) -> BifurcationPoint:
    """The bifurcation located by `_bisect` at `z` (its resolution `width`, the
    trials either side `sides`, and whether it `stopped` at the corrector's
    failures) after the converged point i, classified as `locate_bifurcations`
    says: its kind, p and critical multiplier."""
    record = _record(problem, z)
    _, m = _critical(record)
    p = z[-1]
    if stopped:  # regula falsi between the converged points either side
        (f_a, z_a), (f_b, z_b) = sides
        p = z_a[-1] + (z_b[-1] - z_a[-1]) * f_a / (f_a - f_b)
    if fold and _through_steady_sliding(branch, record, i):
        kind, p = "Hopf", _hopf_p(branch, i, p)
    elif fold:
        kind = "fold"
    elif sides[1] is not None and abs(sides[1][0] - sides[0][0]) > JUMP:
        kind, zeros = _discontinuity(problem, sides)
        point = (_sliding(problem, algorithm, sides, zeros)
                 if kind == "sliding" and exact_problem(problem) else None)
        if point is not None and point.converged:  # on its defining condition
            p, z, width, record = point.p, point.z, float(point.step), point.record
            _, m = _critical(record)
    elif abs(m.imag) > 1e-6 * max(1.0, abs(m)) and abs(m.imag) > 1e-3:
        kind = "Neimark-Sacker"
    elif m.real < 0:
        kind = "period doubling"
    else:
        kind = "branch point"
    return BifurcationPoint(kind=kind, p=p, z=z, multiplier=jnp.asarray(m),
                            record=record, after=int(i), width=float(width))


def locate_bifurcations(problem: ContinuationProblem, branch: Branch,
                        algorithm: PseudoArclength = PseudoArclength(), *,
                        steps: int = 24) -> tuple[BifurcationPoint, ...]:
    """Classify and locate the folds and changes of stability of a branch of
    periodic orbits (`continuation` of `cycle_problem`).

    Between two converged points z_i, z_(i+1) where dp/ds changes sign (a fold) or
    the largest non-trivial Floquet multiplier leaves the unit circle, the point is
    located by bisection on the arclength s along the tangent t_i: each trial point
    is z_i + s t_i corrected onto the branch (the pseudo-arclength corrector), and
    the test function is dp/ds (fold) or |mu| - 1 (the critical multiplier mu). This
    needs no extended system, so it converges where many multipliers crowd near +1
    (a weakly coupled chain). Where the corrector fails all around the change (a
    branch point, where [G_u, G_p] is nearly singular), the bisection stops outside
    that interval, and p is the zero of the test function's linear interpolation
    between the converged points either side (regula falsi; `width` is then their
    distance in arclength). The kind follows from the multiplier at the located
    point (`BIFURCATION_KINDS`); a turning point at zero amplitude, where the branch
    passes through steady sliding (`HOPF_ENERGY`), is a "Hopf" point, its p the zero
    of the energy extrapolated along the branch (`_hopf_p`). A change of stability is
    classified by its multiplier, unless the multiplier jumps by more than `JUMP`
    across the last interval: a discontinuity-induced bifurcation of the exact
    model, "sliding" where a stick phase appears or vanishes (the count of zero
    multipliers changes) and "grazing" otherwise (`_discontinuity`). A sliding
    bifurcation is then located on its own defining condition, the stick phase's
    vanishing duration (`locate_sliding`); where that does not converge, the
    bisection's point stays. A branch point where no stability changes (on a
    branch unstable already) is found by the sign of the bordered determinant
    (`Branch.branch_points`) and located by bisection on it (`_branch_points`).
    An exact branch whose corrector failed beyond its last
    orbit ends with the sliding bifurcation located from that orbit, if there is one
    between it and the failed prediction (`after` is then the last point).

    **Arguments:**

    - `problem`: the branch's `ContinuationProblem` (with `describe` giving a
        `PeriodicOrbit`).
    - `branch`: its `Branch`.
    - `algorithm`: the corrector (`PseudoArclength`).
    - `steps`: bisection steps (the interval shrinks by 2^-steps).

    **Returns:**

    The `BifurcationPoint`s, in the order of the branch.

    **Raises:**

    `ValidationError` if `problem.describe` is None (no multipliers to classify by).
    """
    if problem.describe is None:
        raise ValidationError("problem.describe is None: bifurcations are classified by the "
                              "Floquet multipliers of its records")
    ok = np.asarray(branch.converged)
    zs = jnp.concatenate([branch.u, branch.p[:, None]], axis=1)[ok]
    tangents = branch.tangent[ok]
    folds = set(branch.folds)
    found = []
    for i in sorted(folds | set(branch.stability_changes)):
        point = _locate_change(problem, algorithm, branch, zs, tangents, i, i in folds, steps)
        if point is not None:
            found.append(point)
    # beside a sliding point the exact Jacobian jumps, and a sign change there need
    # not pass through zero; but where a symmetric pair of sites loses its stick
    # phases at once, other branches do leave there (the ring of 20's eighteen-site
    # branch meets a sixteen-site one at its sliding point 1.73099), so those are
    # kept and switched at like any other
    found += _branch_points(problem, algorithm, branch, zs, tangents, steps)
    found.sort(key=lambda b: b.after)
    end = _sliding_end(problem, algorithm, branch, zs)
    return tuple(found) + ((end,) if end is not None else ())


#: A branch point located by the sign of the bordered determinant has a non-trivial
#: real Floquet multiplier within this distance of +1 (the multiplier whose
#: crossing it is); a sign change without one is the exact model's Jacobian
#: jumping at a switch, not a branch point.
BRANCH_MULTIPLIER = 1e-2


def _branch_points(problem: ContinuationProblem, algorithm: PseudoArclength, branch: Branch,
                   zs, tangents, steps: int) -> list[BifurcationPoint]:
    """The branch points where the sign of det [[G_u, G_p], [t^T]] changes
    (`Branch.branch_points`) and the stability does not (there the change of
    stability locates and classifies them): on a branch that is unstable already a
    second multiplier crossing +1 changes no stability. Each is located by
    bisection on that sign (`_bisect`) and kept where the orbit there has a real
    non-trivial multiplier within `BRANCH_MULTIPLIER` of +1 and, on the exact
    model, the same number of stick phases on both sides (else the sign jumped
    with the Jacobian at a sliding point)."""
    found = []
    for i in sorted(set(branch.branch_points) - set(branch.stability_changes)):
        z0, t0 = zs[i], tangents[i]

        def test(s, z0=z0, t0=t0):
            new, good, _, _ = _correct(problem, algorithm, z0 + s * t0, t0)
            return (float(_tangent(problem, new, t0)[1]), new) if bool(good) else None

        f_hi = float(_tangent(problem, zs[i + 1], tangents[i + 1])[1])
        s, width, z, sides, _ = _bisect(test, float(t0 @ (zs[i + 1] - z0)), steps, f_hi)
        if z is None:
            continue
        record = _record(problem, z)
        values = np.delete(np.asarray(record.multipliers), int(record.trivial))
        real = values[np.abs(values.imag) <= 1e-6 * np.maximum(1.0, np.abs(values))].real
        if not real.size or np.min(np.abs(real - 1.0)) > BRANCH_MULTIPLIER:
            continue
        if hasattr(record, "zero_multipliers"):
            ends = [_record(problem, side[1]) if side is not None else None
                    for side in sides]
            ends[1] = ends[1] or _record(problem, zs[i + 1])
            if int(ends[0].zero_multipliers) != int(ends[1].zero_multipliers):
                continue
        m = real[np.argmin(np.abs(real - 1.0))]
        found.append(BifurcationPoint(kind="branch point", p=z[-1], z=z,
                                      multiplier=jnp.asarray(complex(m)), record=record,
                                      after=int(i), width=float(width)))
    return found


def _through_steady_sliding(branch: Branch, record, i: int) -> bool:
    """Whether the turning point after converged point i, with the `record` of its
    located orbit, lies on steady sliding (`HOPF_ENERGY`)."""
    if not hasattr(record, "energy"):
        return False
    either_side = np.asarray(branch.records.energy)[i:i + 2]
    return float(record.energy) < HOPF_ENERGY * float(either_side.min())


def _hopf_p(branch: Branch, i: int, fallback) -> Float[Array, ""]:
    """The Hopf point where a branch passes through steady sliding after converged
    point i: the squared amplitude, and so the energy (eq. (9)), of the cycle is
    linear in p to leading order there (Kuznetsov 2004, Sect. 3.5), so p is the zero,
    nearest point i, of the parabola through the energies of the three converged
    points up to i (two: the line). The located turning point itself is not: at
    zero amplitude the corrector may converge to steady sliding, which solves
    shooting at any p. `fallback` where fewer than two points precede it."""
    p = np.asarray(branch.p)[np.asarray(branch.converged)][max(i - 2, 0):i + 1]
    energy = np.asarray(branch.records.energy)[max(i - 2, 0):i + 1]
    if p.size < 2:
        return fallback
    roots = np.roots(np.polyfit(p, energy, p.size - 1))
    roots = roots[np.isreal(roots)].real
    return jnp.asarray(roots[np.argmin(np.abs(roots - p[-1]))]) if roots.size else fallback


def _sliding_end(problem: ContinuationProblem, algorithm: PseudoArclength, branch: Branch,
                 zs) -> BifurcationPoint | None:
    """The sliding bifurcation at the end of an exact branch whose corrector failed
    beyond its last orbit (a branch of stick-slip orbits ends where a stick phase
    vanishes, and no orbit of the same segments lies beyond), located by
    `locate_sliding` from the last orbit and the two before it, if it lies beyond
    that orbit towards the failed prediction after it, no farther than that
    prediction or the last three orbits reach; else None. `after` is the last
    point's index: no point of the branch follows."""
    if branch.stop != Status.newton_failed or not exact_problem(problem):
        return None
    z, beyond = zs[-1], float(branch.p[-1])
    if not np.isfinite(_phases(problem, z)).any():
        return None
    step = beyond - float(z[-1])
    point = locate_sliding(problem, z, algorithm, delta=abs(step), seeds=zs[-3:-1])
    # beyond the last orbit, where the failed step went, as far as that step or the
    # last three orbits reach (the steps shrink towards the square root's singularity)
    reach = max(abs(step), abs(float(z[-1]) - float(zs[max(len(zs) - 3, 0)][-1])))
    if not point.converged or not 0 <= (float(point.p) - float(z[-1])) * np.sign(step) <= reach:
        return None
    _, m = _critical(point.record)
    return BifurcationPoint(kind="sliding", p=point.p, z=point.z, multiplier=jnp.asarray(m),
                            record=point.record, after=len(zs) - 1, width=float(point.step))
