"""Following a branch of periodic orbits: the one driver of every study that
continues orbits (the snake, the bistable range, the mistuning study's edges),
for any orbit method.

`follow_branch` continues a branch by pseudo-arclength (`continuation`) both ways
from an orbit, locates its bifurcations (`locate_bifurcations`) and applies the
steps that carry a branch of friction oscillators' orbits where plain continuation
stops or goes astray, each named by what it does and where it comes from:

- **past sliding points**: where a branch of exact stick-slip orbits ends at a
    sliding bifurcation, it goes on onto the orbits without that stick phase
    (`past_sliding_start`; di Bernardo, Budd, Champneys and Kowalczyk,
    *Piecewise-smooth Dynamical Systems* (2008), Sect. 8.5);
- **cut at a Hopf point**: a branch that reaches steady sliding at its Hopf point
    ends there (beyond it, the same cycles half a period on);
- **closed isolas**: a branch that comes back through its start is an isola, cut
    where it closes (Seydel, *Practical Bifurcation and Stability Analysis*, 3rd ed.
    (2010), Sect. 2.9);
- **cut where it retraces itself**: a branch that turns at a fold onto the image of
    what it came through under a symmetry of the ring ends at that fold (equivariant
    bifurcation theory: Golubitsky, Stewart and Schaeffer, *Singularities and Groups
    in Bifurcation Theory*, Vol. II (1988));
- **branch switching** at branch points: Keller's step along the kernel direction
    the followed branch does not take (`switch_branch`; Keller, *Numerical solution
    of bifurcation and nonlinear eigenvalue problems* (1977)); where it fails,
    deflation beside the point (`switch_by_deflation`; Farrell, Birkisson and Funke,
    SIAM J. Sci. Comput. 37 (2015)); where that finds nothing, Keller's step along
    each axis of the critical plane that a symmetry of the orbit fixes
    (`symmetric_directions`, the equivariant branching lemma of Golubitsky, Stewart
    and Schaeffer (1988), ch. XIII).

The result is a `FollowedBranch`: typed arrays over the branch's converged points,
its located bifurcations, how each end stopped and the branches switched onto.
With `store`, it is written to a file when done and read back by a later call with
equal settings (`branch_file.py`).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import jax.numpy as jnp
import numpy as np

from .bifurcations import BifurcationPoint, locate_bifurcations
from .branch_switching import switch_branch, switch_by_deflation, symmetric_directions
from .continuation import Branch, ContinuationOptions, PseudoArclength, continuation
from .orbit_method import AbstractOrbitMethod, PeriodicOrbit
from .past_sliding import past_sliding_start
from .periodic_orbit import cycle_method, cycle_problem, periodic_orbit
from .symmetry import isotropy
from .._engine.status import Status
from .._physics.params import ChainParams, with_parameter

#: Sliding bifurcations that one continuation goes on through, at most.
SLIDING_PASSES = 4

#: The arrays of a `FollowedBranch`, one value per converged point.
POINT_ARRAYS = ("p", "u", "energy", "period", "n_halc", "stable", "critical_multiplier_abs",
                "trivial_multiplier_error", "amplitudes")


@dataclasses.dataclass(frozen=True)
class LocatedBifurcation:
    """A bifurcation on a followed branch (`BifurcationPoint` without its solution).

    **Fields:** `kind` (one of `BIFURCATION_KINDS`); `p`, the continued parameter
    there (dimensionless, eq. (6)); `energy` (eq. (9)) and `n_halc` of its orbit;
    `multiplier`, the critical Floquet multiplier; `after`, the index of the
    branch's point after which it lies; `width`, the location's resolution."""

    kind: str
    p: float
    energy: float
    multiplier: complex
    n_halc: int
    after: int
    width: float

    @classmethod
    def of(cls, point: BifurcationPoint) -> LocatedBifurcation:
        return cls(point.kind, float(point.p), float(point.record.energy),
                   complex(np.asarray(point.multiplier)), int(point.record.n_halc),
                   point.after, point.width)

    def moved(self, after: int) -> LocatedBifurcation:
        """The same bifurcation, after the point `after` of another branch."""
        return dataclasses.replace(self, after=after)


@dataclasses.dataclass(frozen=True)
class SwitchFailure:
    """A branch point where no step onto the other branch converged: its `p` and
    the `reason`."""

    p: float
    reason: str


@dataclasses.dataclass(frozen=True)
class FollowedBranch:
    """A branch of periodic orbits as `follow_branch` gives it.

    **Fields:**

    - `p`: the continued parameter at each converged point, shape (points,).
    - `u`: the method's unknowns there, shape (points, unknowns).
    - `energy` (eq. (9)), `period`, `n_halc`, `stable`, the largest non-trivial
        |multiplier| `critical_multiplier_abs` and the trivial multiplier's distance
        from 1 `trivial_multiplier_error`, each shape (points,); `amplitudes`, shape
        (points, n_osc).
    - `bifurcations`: the `LocatedBifurcation`s in the order of the branch.
    - `stops`: how each end stopped: {"low": ..., "high": ...} for a branch
        followed both ways, {"away": ...} for one switched onto, {"end": ...} for one
        way; a `Status` name of the continuation, or "closed" (an isola, closed on
        itself), "retraced" (it turns at a fold onto its own image) or "hopf" (it
        reaches steady sliding).
    - `phase_oscillator`: the oscillator of the method's phase condition.
    - `switched_from`: for a branch switched onto, p at its branch point.
    - `switched`: the branches switched onto at its branch points.
    - `failed_switches`: the branch points where switching failed (`SwitchFailure`).
    - `pieces`: each continuation's (`ContinuationProblem`, `Branch`, its
        `BifurcationPoint`s), in the order they were made (down, then up), uncut:
        for what a study refines further (a fold by `fold_point`).
    """

    p: np.ndarray
    u: np.ndarray
    energy: np.ndarray
    period: np.ndarray
    n_halc: np.ndarray
    stable: np.ndarray
    critical_multiplier_abs: np.ndarray
    trivial_multiplier_error: np.ndarray
    amplitudes: np.ndarray
    bifurcations: tuple[LocatedBifurcation, ...]
    stops: dict
    phase_oscillator: int
    switched_from: float | None = None
    switched: tuple[FollowedBranch, ...] = ()
    failed_switches: tuple[SwitchFailure, ...] = ()
    pieces: tuple = dataclasses.field(default=(), repr=False, compare=False)

    @property
    def points(self) -> int:
        return len(self.p)

    def take(self, index, **changes) -> FollowedBranch:
        """The branch at the points `index` (a slice or indices), with `changes`."""
        return dataclasses.replace(self, **{k: getattr(self, k)[index] for k in POINT_ARRAYS},
                                   **changes)


def _concat(parts: list[FollowedBranch], **changes) -> FollowedBranch:
    """The points of `parts` one after another, the first's other fields, `changes`."""
    return dataclasses.replace(parts[0], **{k: np.concatenate([getattr(b, k) for b in parts])
                                            for k in POINT_ARRAYS}, **changes)


def _piece(problem, branch: Branch, bifurcations: list) -> FollowedBranch:
    """One continuation's converged points and bifurcations."""
    ok = np.asarray(branch.converged)
    r = branch.records
    multipliers = np.asarray(r.multipliers)
    return FollowedBranch(
        p=np.asarray(branch.p)[ok], u=np.asarray(branch.u)[ok],
        energy=np.asarray(r.energy), period=np.asarray(r.period),
        n_halc=np.asarray(r.n_halc), stable=np.asarray(branch.stable),
        critical_multiplier_abs=np.abs(np.asarray(r.critical_multiplier)),
        trivial_multiplier_error=np.abs(
            np.take_along_axis(multipliers, np.asarray(r.trivial)[:, None], 1)[:, 0] - 1),
        amplitudes=np.asarray(r.amplitudes),
        bifurcations=tuple(LocatedBifurcation.of(b) for b in bifurcations),
        stops={"end": branch.stop.name},
        phase_oscillator=cycle_method(problem).phase_oscillator)


def follow_branch(orbit: PeriodicOrbit, method: AbstractOrbitMethod,
                  options: ContinuationOptions,
                  algorithm: PseudoArclength = PseudoArclength(), *,
                  directions: tuple[int, ...] = (-1, 1), switch: bool = False,
                  store: str | Path | None = None, progress: bool = False
                  ) -> FollowedBranch:
    """The branch of periodic orbits through `orbit`, continued over the belt
    speed v_d each way of `directions`, on past sliding
    points, cut at a Hopf point, where it closes on itself (an isola; the other way
    is then not continued: both its stops are "closed") and where it retraces
    itself, its bifurcations located; with `switch`, at each branch point that the
    branch keeps and whose orbit has a site on the HALC, the other branches through
    it are followed too (`FollowedBranch.switched`, each cut where it repeats
    itself up to the ring's symmetry); the others join cycles without stick, not
    localized states. The steps and their sources: this module's docstring.

    **Arguments:**

    - `orbit`: a converged `PeriodicOrbit` to start from (its `params.v_d` is where
        the branch starts).
    - `method`: the orbit method of every orbit (`Shooting(...)`), its phase
        condition included (`with_phase_oscillator`).
    - `options`: `ContinuationOptions`, each direction's budget (their
        `direction` is replaced by each of `directions`).
    - `algorithm`: `PseudoArclength` (its Newton tolerance and steps).
    - `directions`: (-1, 1) for both ways (the points then run from low to high
        along the branch), (1,) or (-1,) for one.
    - `switch`: follow the branches through its branch points.
    - `store`: a netCDF file: the branch is written there when it is done (and each
        branch switched onto beside it, `<stem>_switched<j>.nc`), under the key of
        every argument above, the start's orbit and chain included; a later call
        with equal arguments reads it back instead of computing it (resume). A
        branch read back has no `pieces`.
    - `progress`: progress bars.

    **Returns:** `FollowedBranch` (`stops` {"low", "high"} for both ways, {"end"}
    for one).

    **Raises:** what `continuation` raises (`ValidationError` for bad options);
    `RuntimeError` where a continuation cannot start.
    """
    if store is None:
        return _followed(orbit, method, options, algorithm, directions, switch, progress)
    from .branch_file import read_followed, write_followed  # it builds on this module

    key = {"params": orbit.params, "start": [orbit.y0, orbit.period], "method": method,
           "options": options, "algorithm": algorithm, "directions": list(directions),
           "switch": bool(switch), "sliding_passes": SLIDING_PASSES}
    followed = read_followed(store, **key)
    if followed is None:
        followed = _followed(orbit, method, options, algorithm, directions, switch, progress)
        write_followed(store, followed, **key)
    return followed


def _followed(orbit: PeriodicOrbit, method: AbstractOrbitMethod, options, algorithm,
              directions: tuple, switch: bool, progress: bool) -> FollowedBranch:
    """`follow_branch` without its store."""
    problem = cycle_problem(orbit, method)
    halves, switched = [], []
    for direction in directions:
        if halves and halves[0].stops["end"] == "closed":  # an isola: all of it is known
            halves.append(halves[0].take([0], bifurcations=(), stops={"end": "closed"},
                                         pieces=()))
            continue
        opts = dataclasses.replace(options, direction=direction)
        pieces = _through_sliding(problem, algorithm, opts, progress=progress)
        half = _closed_loop(method, orbit.params, orbit, _joined_pieces(pieces))
        halves.append(half if half.stops["end"] == "closed" else
                      _retraced(method, orbit.params, half))
        if switch:
            kept = {b.p for b in halves[-1].bifurcations}
            switched += [sw for piece, branch, bifs in pieces for b in bifs
                         if b.kind == "branch point" and float(b.p) in kept
                         and int(b.record.n_halc) > 0
                         for sw in _switched_branches(method, piece, branch, b, options,
                                                      algorithm, progress=progress)]
    failures = tuple(sw for sw in switched if isinstance(sw, SwitchFailure))
    others = tuple(sw for sw in switched if not isinstance(sw, SwitchFailure))
    if len(halves) == 1:
        return dataclasses.replace(halves[0], switched=others, failed_switches=failures)
    down, up = halves
    last = down.points - 1
    # "after": the first of the two joined points that the bifurcation lies between
    bifs = ([b.moved(last - b.after - 1) for b in down.bifurcations][::-1]
            + [b.moved(last + b.after) for b in up.bifurcations])
    return _concat([down.take(slice(None, None, -1)), up.take(slice(1, None))],
                   bifurcations=tuple(bifs),
                   stops={"low": down.stops["end"], "high": up.stops["end"]},
                   switched=others, failed_switches=failures, pieces=down.pieces + up.pieces)


def _through_sliding(problem, algorithm: PseudoArclength, options: ContinuationOptions, *,
                     tangent=None, progress: bool = False) -> list[tuple]:
    """Continue from `problem.u0` (`continuation`) and locate the bifurcations; where
    the branch of exact orbits ends at a sliding bifurcation, go on past it onto the
    orbits without that stick phase (`past_sliding_start`), each time with
    `options`' budget, up to `SLIDING_PASSES` times. Returns the pieces in order,
    each (its problem, `Branch`, bifurcations)."""
    pieces = []
    for _ in range(SLIDING_PASSES + 1):
        branch = continuation(problem, algorithm, options, tangent=tangent, progress=progress)
        bifs = locate_bifurcations(problem, branch, algorithm)
        pieces.append((problem, branch, bifs))
        if any(b.kind == "Hopf" for b in bifs):  # beyond it: the same cycles again
            break
        ok = np.asarray(branch.converged)
        # a branch that ends (its corrector failed beyond) at a sliding point, beyond
        # its last orbit or between its last two: the last may lie on the other
        # family through the point (no stick phase, unstable)
        ends = [b for b in bifs if b.kind == "sliding" and b.after >= int(ok.sum()) - 2
                and branch.stop == Status.newton_failed]
        # from the branch's last orbits: the sliding point's own orbit, solved near
        # it, may lie on another branch through the same point; and the last orbit,
        # at the point, may have lost its stick phase already (the two families meet
        # there), so the two before it are tried too
        last = [jnp.append(u, p) for u, p in zip(branch.u[ok][-3:], branch.p[ok][-3:])]
        start = next((s for z in last[::-1] if ends
                      for s in [past_sliding_start(problem, z, algorithm)] if s is not None),
                     None)
        if start is None:
            break
        problem, tangent = start
    return pieces


def _joined_pieces(pieces: list) -> FollowedBranch:
    """The pieces of `_through_sliding` joined in order: the bifurcations' `after`
    counted along the whole, the last piece's stop. A branch that passes through
    steady sliding (a "Hopf" bifurcation) is cut there, its stop "hopf": beyond,
    its unknowns are those of the same cycles half a period on, which it came
    through already."""
    parts = [_piece(*piece) for piece in pieces]
    bifs, offset = [], 0
    for part in parts:
        bifs += [b.moved(offset + b.after) for b in part.bifurcations]
        offset += part.points
    joined = _concat(parts, bifurcations=tuple(bifs), stops=parts[-1].stops,
                     pieces=tuple(pieces))
    hopf = [b for b in bifs if b.kind == "Hopf"]
    if not hopf:
        return joined
    end = hopf[0].after
    return joined.take(slice(0, end + 1),
                       bifurcations=tuple(b for b in bifs if b.after < end) + (hopf[0],),
                       stops={"end": "hopf"})


def _first_away(branch: FollowedBranch, first: int = 0) -> int | None:
    """The first point after point `first` of `branch` whose signature (amplitudes
    sorted by size, period, p) differs from that point's by more than 0.1, or None."""
    signature = np.column_stack([np.sort(branch.amplitudes, axis=1), branch.period, branch.p])
    away = np.flatnonzero(np.max(np.abs(signature[first:] - signature[first]), axis=1) > 0.1)
    return None if away.size == 0 else first + int(away[0])


def _closed_loop(method, params: ChainParams, orbit, half: FollowedBranch, *,
                 first: int = 0, images: bool = False) -> FollowedBranch:
    """`half`, a branch continued one way, cut where it comes back through `orbit`,
    its point `first` at `params`, itself (`passes_through` with `images` False,
    after the first point where its signature has left that point's by more than
    0.1): the branch is an isola, closed on itself, and its stop is "closed".
    Unchanged where it does not come back, or comes back through an image of
    `orbit` under a reflection of the ring (it retraces itself beyond a fold:
    `_retraced`). With `images`, a return through an image of `orbit` closes it
    too: from there on the branch is the image of what it has traced (closed up to
    the ring's symmetry)."""
    start = _first_away(half, first)
    if start is None:
        return half
    i = passes_through(method, params, orbit, half.take(slice(start, None)), images=images)
    if i is None:
        return half
    end = start + i + 1
    return half.take(slice(0, end + 1),
                     bifurcations=tuple(b for b in half.bifurcations if b.after < end),
                     stops={"end": "closed"})


def _repeats_itself(method, params: ChainParams, branch: FollowedBranch) -> FollowedBranch:
    """A switched branch cut where it comes back through one of its own orbits or
    an image of it (`_closed_loop` with `images`, stop "closed"): beyond, it repeats
    what it has traced, up to the ring's symmetry. The orbit compared is its first
    point more than 0.1 from its start in signature, not the start itself, which
    lies beside a branch point, often at a fold, where shooting from the branch's
    interpolated points can land on either sheet."""
    j = _first_away(branch)
    if j is None:
        return branch
    probe = _Probe(branch.amplitudes[j], float(branch.period[j]))
    at = with_parameter(params, "v_d", float(branch.p[j]))
    return _closed_loop(method, at, probe, branch, first=j, images=True)


@dataclasses.dataclass(frozen=True)
class _Probe:
    """A point of a branch as `passes_through` compares it."""

    amplitudes: np.ndarray
    period: float


def _retraced(method, params: ChainParams, half: FollowedBranch) -> FollowedBranch:
    """`half`, a branch continued one way, cut at its first fold beyond which it
    retraces itself: where the point three steps past the fold is an orbit of the
    branch before it (`passes_through`), the branch has turned at an orbit fixed
    by a symmetry of the ring (a reflection, with the pattern's two halves
    exchanged) and goes on as the image of what it came through. Its stop is then
    "retraced", the fold its last bifurcation. Unchanged where no fold is."""
    for fold in (b for b in half.bifurcations if b.kind == "fold"):
        i, j = fold.after, fold.after + 3
        if j >= half.points:
            break
        probe = _Probe(half.amplitudes[j], float(half.period[j]))
        at = with_parameter(params, "v_d", float(half.p[j]))
        if passes_through(method, at, probe, half.take(slice(0, i + 1))) is not None:
            return half.take(slice(0, i + 1),
                             bifurcations=tuple(b for b in half.bifurcations if b.after <= i),
                             stops={"end": "retraced"})
    return half


def _switched_branches(method, problem, branch: Branch, point: BifurcationPoint,
                       options: ContinuationOptions, algorithm: PseudoArclength, *,
                       progress: bool) -> list:
    """The other branches through the branch point `point` of `branch` (a branch of
    `problem`, whose orbits `method` solves, held oscillators apart), each
    continued away from it for `options.max_points` points, with its bifurcations,
    and cut where it repeats itself (`_repeats_itself`; stops {"away": ...}).
    The step onto the other branch is Keller's (`switch_branch`); where it does not
    converge (a symmetric ring, where the kernel has more directions), the orbits
    that deflation finds beside the branch point (`switch_by_deflation`), and where
    that finds none, Keller's step along each axis of the orbit's symmetry in the
    kernel (`_switch_along_axes`). Where none finds one, a `SwitchFailure`."""
    try:
        starts = [switch_branch(problem, branch, point, algorithm=algorithm)]
    except RuntimeError as err:
        starts = (switch_by_deflation(problem, branch, point, algorithm=algorithm)
                  or _switch_along_axes(problem, branch, point, algorithm))
        if not starts:
            return [SwitchFailure(float(point.p), f"{err}; deflation beside it found no "
                                  "other orbit, nor a step along an axis of its symmetry")]
    out = []
    for new, tangent in starts:
        away = _joined_pieces(_through_sliding(new, algorithm, options, tangent=tangent,
                                               progress=progress))
        away = _repeats_itself(method.with_phase_oscillator(away.phase_oscillator),
                               new.params, away)
        out.append(dataclasses.replace(away, switched_from=float(point.p),
                                       stops={"away": away.stops["end"]}))
    return out


def _switch_along_axes(problem, branch: Branch, point: BifurcationPoint,
                       algorithm: PseudoArclength) -> list:
    """Keller's step (`switch_branch`) from the branch point `point` along each axis
    of the critical plane that a symmetry of its orbit fixes
    (`symmetric_directions`, with the orbit's isotropy subgroup, `isotropy`), to
    both sides: the (problem, tangent) of each that converges. Tried where the
    kernel direction and deflation beside the point fail: the whole ring of 20's
    branch point with a double multiplier +1. Empty for an orbit with no
    symmetry. The symmetry acts on the unknowns (x, x', T) of shooting."""
    z = np.asarray(point.z)
    y = z[:-2].reshape(2, -1)  # z = (x, x', T, v_d)
    # its symmetry holds to Newton's tolerance (1e-9): 1e-6 keeps it, and separates
    # patterns that differ by their sites' amplitudes
    perms = isotropy(problem.params, y, atol=1e-6)
    if len(perms) < 2:
        return []
    n = y.shape[1]
    actions = [np.concatenate([p, n + p, [2 * n, 2 * n + 1]]) for p in perms]
    tangent = branch.tangent[np.nonzero(np.asarray(branch.converged))[0][point.after]]
    out = []
    for axis in symmetric_directions(problem, point.z, tangent, actions):
        for side in (1, -1):
            try:
                out.append(switch_branch(problem, branch, point, side=side,
                                         algorithm=algorithm, direction=axis))
            except RuntimeError:
                continue
    return out


def passes_through(method, params: ChainParams, orbit, branch: FollowedBranch,
                    tol: float = 1e-6, *, images: bool = True) -> int | None:
    """The first point i of `branch` such that the branch passes through the
    periodic orbit `orbit` (at `params.v_d`) between points i and i + 1, or None.
    Where the branch crosses v_d between two points whose interpolated period and
    amplitudes sorted by size (a signature no rotation or reflection changes) lie
    within 0.1 of the orbit's, the orbit of the branch at v_d is solved by `method`
    from the interpolated point; the same orbit when its signature agrees within
    `tol` (both are solved to Newton's tolerance). `orbit`: anything with
    `amplitudes`, shape (n_osc,), and `period`. With `images` False, only `orbit`
    itself counts, not its images under the ring's rotations and reflections: the
    solved orbit's unknowns must then agree with `orbit`'s within `tol` (both with
    the branch's phase condition)."""
    v0 = float(params.v_d)
    signature = np.append(np.sort(np.asarray(orbit.amplitudes)), float(orbit.period))
    v, u = branch.p, branch.u
    known = np.column_stack([np.sort(branch.amplitudes, axis=1), branch.period])
    for i in np.flatnonzero((v[:-1] - v0) * (v[1:] - v0) <= 0):
        w = 0.0 if v[i + 1] == v[i] else (v0 - v[i]) / (v[i + 1] - v[i])
        if np.max(np.abs(known[i] + w * (known[i + 1] - known[i]) - signature)) > 0.1:
            continue
        y, period = method.orbit(jnp.asarray(u[i] + w * (u[i + 1] - u[i])))
        shot = periodic_orbit(params, (y, period), method, throw=False)
        found = np.append(np.sort(np.asarray(shot.amplitudes)), float(shot.period))
        same = images or np.max(np.abs(np.append(np.ravel(shot.y0), float(shot.period))
                                       - np.append(np.ravel(orbit.y0), float(orbit.period)))
                                ) < tol
        if bool(shot.converged) and np.max(np.abs(found - signature)) < tol and same:
            return int(i)
    return None
