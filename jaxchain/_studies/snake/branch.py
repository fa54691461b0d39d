"""One branch of the snake: pseudo-arclength continuation of a periodic orbit
over the belt speed, its bifurcations located, through sliding points, closed on
itself where it is an isola, and the branches switched onto at its branch points."""

from __future__ import annotations

import dataclasses
import json
from typing import TYPE_CHECKING, NamedTuple

import jax.numpy as jnp
import numpy as np

from ..._bifurcation.bifurcations import locate_bifurcations
from ..._bifurcation.branch_switching import (
    switch_branch,
    switch_by_deflation,
    symmetric_directions,
)
from ..._bifurcation.continuation import ContinuationOptions, PseudoArclength, continuation
from ..._bifurcation.periodic_orbit import cycle_method
from ..._bifurcation.past_sliding import past_sliding_start
from ..._bifurcation.shooting import pack, unpack
from ..._engine.status import Status
from ..._physics.params import ChainParams, with_parameter
from .starts import isotropy

if TYPE_CHECKING:  # heavy: imported where they are used
    import xarray as xr


#: Continuation of each branch: far enough each way (150 points) to pass its folds.
SNAKE_CONTINUATION = ContinuationOptions(ds=0.02, ds_max=0.1, p_min=1.0, p_max=2.2,
                                         max_points=150)


def _branch_dataset(k: int, problem, branch, bifurcations) -> xr.Dataset:
    import xarray as xr

    ok = np.asarray(branch.converged)
    r = branch.records
    multipliers = np.asarray(r.multipliers)
    return xr.Dataset(
        {"energy": ("point", np.asarray(r.energy)),
         "period": ("point", np.asarray(r.period)),
         "n_halc": ("point", np.asarray(r.n_halc)),
         "stable": ("point", np.asarray(branch.stable)),
         "critical_multiplier_abs": ("point", np.abs(np.asarray(r.critical_multiplier))),
         "trivial_multiplier_error": ("point", np.abs(
             np.take_along_axis(multipliers, np.asarray(r.trivial)[:, None], 1)[:, 0] - 1)),
         "amplitudes": (("point", "osc"), np.asarray(r.amplitudes)),
         "u": (("point", "unknown"), np.asarray(branch.u)[ok])},
        coords={"v_d": ("point", np.asarray(branch.p)[ok])},
        attrs={"excited": k, "phase_oscillator": cycle_method(problem).phase_oscillator,
               "stop": branch.stop.name,
               "bifurcations": json.dumps([
                   {"type": b.kind, "v_d": float(b.p), "energy": float(b.record.energy),
                    "multiplier": [float(np.real(b.multiplier)), float(np.imag(b.multiplier))],
                    "n_halc": int(b.record.n_halc), "after": b.after, "width": b.width}
                   for b in bifurcations])})


def _follow_branch(orbits, orbit, phase_oscillator: int,
                   continuation_options: ContinuationOptions,
                   algorithm: PseudoArclength = PseudoArclength(), *, k: int = 0,
                   switch: bool = False, progress: bool = False
                   ) -> tuple[xr.Dataset, list[xr.Dataset]]:
    """Continue the branch of periodic orbits through `orbit` over v_d both ways
    (pseudo-arclength, `continuation`), on through the sliding bifurcations where a
    branch of exact orbits ends (`_through_sliding`), join the two halves in the
    order of the branch, and locate its bifurcations (`locate_bifurcations`); with
    `switch`, at each branch point follow the other branch through it
    (`_switched_branch`): at those the branch keeps (not past a cut) whose orbit
    has a site on the HALC (the others join cycles without stick, not localized
    states).
    A branch that comes back through `orbit` is an isola: it is cut there
    (`_closed_loop`), the other way is not continued, and both its stops are
    "closed". A way that turns at a fold onto its own mirror image is cut at the
    fold (`_retraced`, stop "retraced"), one that passes through steady sliding at
    its Hopf point (`_pieces_dataset`, stop "hopf").

    **Returns:**

    (the branch, the switched branches). Each an `xarray.Dataset` over the
    converged points (dim `point`, coordinate `v_d`):
    energy (eq. (9)), period, n_halc, stable, the largest non-trivial |multiplier|,
    the trivial multiplier's distance from 1, amplitudes (point, osc) and the
    shooting unknowns u; attributes `bifurcations` (JSON list of type, v_d, energy,
    multiplier, n_halc, and `after`: the index of the point before it), `stop`, and
    `failed_switches` (JSON list of the branch points where the switch failed: v_d,
    reason).
    """
    import xarray as xr

    problem = orbits.problem(orbit, phase_oscillator)
    halves, switched = [], []
    for direction in (-1, 1):
        if halves and halves[0].attrs["stop"] == "closed":  # an isola: all of it is known
            halves.append(halves[0].isel(point=[0]).assign_attrs(
                bifurcations="[]", stop="closed"))
            continue
        opts = dataclasses.replace(continuation_options, direction=direction)
        pieces = _through_sliding(problem, algorithm, opts, progress=progress)
        half = _closed_loop(orbits, orbit.params, orbit, _pieces_dataset(k, pieces))
        halves.append(half if half.attrs["stop"] == "closed" else
                      _retraced(orbits, orbit.params, half))
        # at the branch points the half keeps (not past a cut) whose orbit has a site
        # on the HALC: the others join cycles without stick, not localized states
        kept = {b["v_d"] for b in json.loads(halves[-1].attrs["bifurcations"])}
        if switch:
            switched += [ds for piece, branch, bifs in pieces for b in bifs
                         if b.kind == "branch point" and float(b.p) in kept
                         and int(b.record.n_halc) > 0
                         for ds in _switched_branch(orbits, piece, branch, b,
                                                    continuation_options, algorithm, k=k,
                                                    progress=progress)]
    failures = [sw for sw in switched if isinstance(sw, dict)]
    down, up = halves
    joined = xr.concat([down.isel(point=slice(None, None, -1)), up.isel(point=slice(1, None))],
                       dim="point", data_vars="all")
    # "after": the first of the two joined points that the bifurcation lies between
    last = down.sizes["point"] - 1
    bifs = ([b | {"after": last - b["after"] - 1} for b in json.loads(down.attrs["bifurcations"])]
            [::-1] + [b | {"after": last + b["after"]} for b in
                      json.loads(up.attrs["bifurcations"])])
    joined = joined.assign_attrs(down.attrs | {
        "bifurcations": json.dumps(bifs),
        "stop": json.dumps({"low": down.attrs["stop"], "high": up.attrs["stop"]}),
        "failed_switches": json.dumps(failures)})
    return joined, [ds for ds in switched if not isinstance(ds, dict)]


def _first_away(branch: xr.Dataset, first: int = 0) -> int | None:
    """The first point after point `first` of `branch` whose signature (amplitudes
    sorted by size, period, v_d) differs from that point's by more than 0.1, or
    None."""
    signature = np.column_stack([np.sort(branch["amplitudes"].values, axis=1),
                                 branch["period"].values, branch["v_d"].values])
    away = np.flatnonzero(np.max(np.abs(signature[first:] - signature[first]), axis=1) > 0.1)
    return None if away.size == 0 else first + int(away[0])


def _closed_loop(orbits, params: ChainParams, orbit, half: xr.Dataset, *, first: int = 0,
                 images: bool = False) -> xr.Dataset:
    """`half`, a branch continued one way, cut where it comes back through `orbit`,
    its point `first` at `params`, itself (`_passes_through` with `images` False,
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
    i = _passes_through(orbits, params, orbit, half.isel(point=slice(start, None)),
                        images=images)
    if i is None:
        return half
    end = start + i + 1
    bifs = [b for b in json.loads(half.attrs["bifurcations"]) if b["after"] < end]
    return half.isel(point=slice(0, end + 1)).assign_attrs(bifurcations=json.dumps(bifs),
                                                           stop="closed")


def _repeats_itself(orbits, params: ChainParams, branch: xr.Dataset) -> xr.Dataset:
    """A switched branch cut where it comes back through one of its own orbits or
    an image of it (`_closed_loop` with `images`, stop "closed"): beyond, it repeats
    what it has traced, up to the ring's symmetry. The orbit compared is its first
    point more than 0.1 from its start in signature, not the start itself, which
    lies beside a branch point, often at a fold, where shooting from the branch's
    interpolated points can land on either sheet."""
    j = _first_away(branch)
    if j is None:
        return branch
    probe = _Point(branch["amplitudes"].values[j], float(branch["period"].values[j]))
    at = with_parameter(params, "v_d", float(branch["v_d"].values[j]))
    return _closed_loop(orbits, at, probe, branch, first=j, images=True)


class _Point(NamedTuple):
    """A point of a branch dataset as `_passes_through` compares it."""

    amplitudes: np.ndarray
    period: float


def _retraced(orbits, params: ChainParams, half: xr.Dataset) -> xr.Dataset:
    """`half`, a branch continued one way, cut at its first fold beyond which it
    retraces itself: where the point three steps past the fold is an orbit of the
    branch before it (`_passes_through`, by shooting), the branch has turned at an
    orbit fixed by a symmetry of the ring (a reflection, with the pattern's two
    halves exchanged) and goes on as the image of what it came through. Its stop is
    then "retraced", the fold its last bifurcation. Unchanged where no fold is."""
    bifs = json.loads(half.attrs["bifurcations"])
    for fold in (b for b in bifs if b["type"] == "fold"):
        i, j = fold["after"], fold["after"] + 3
        if j >= half.sizes["point"]:
            break
        probe = _Point(half["amplitudes"].values[j], float(half["period"].values[j]))
        at = with_parameter(params, "v_d", float(half["v_d"].values[j]))
        if _passes_through(orbits, at, probe, half.isel(point=slice(0, i + 1))) is not None:
            return half.isel(point=slice(0, i + 1)).assign_attrs(
                bifurcations=json.dumps([b for b in bifs if b["after"] <= i]), stop="retraced")
    return half


#: Sliding bifurcations that one continuation goes on through, at most.
SLIDING_PASSES = 4


#: Part of the key of stored branches: raise it whenever how a branch is followed
#: changes, so that a resumed run recomputes the branches of an older method
#: (2: through sliding points from the branch's last three orbits, cut at a Hopf
#: point and where it retraces itself; 3: starts not periodic at v_d tried again at
#: `RETRY_VD`; 4: branch points on unstable branches, switched there, switched
#: branches cut where they repeat themselves; 5: starts that lose their pattern
#: tried again, shooting from close recurrences and by the damped Newton method;
#: 6: starts simulated again inside the fixed subspace of their symmetry; 7: branch
#: points switched along the axes of their orbit's symmetry where the others fail).
BRANCH_METHOD = 7


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


def _pieces_dataset(k: int, pieces: list) -> xr.Dataset:
    """The branch dataset (`_branch_dataset`) of the pieces of `_through_sliding`,
    joined in order: the bifurcations' `after` counted along the whole, the last
    piece's stop. A branch that passes through steady sliding (a "Hopf"
    bifurcation) is cut there, its stop "hopf": beyond, its shooting unknowns are
    those of the same cycles half a period on, which it came through already."""
    import xarray as xr

    parts = [_branch_dataset(k, problem, branch, bifs) for problem, branch, bifs in pieces]
    bifs, offset = [], 0
    for part in parts:
        bifs += [b | {"after": offset + b["after"]} for b in json.loads(part.attrs["bifurcations"])]
        offset += part.sizes["point"]
    joined = parts[0] if len(parts) == 1 else xr.concat(parts, dim="point", data_vars="all")
    stop = parts[-1].attrs["stop"]
    hopf = [b for b in bifs if b["type"] == "Hopf"]
    if hopf:
        end = hopf[0]["after"]
        joined = joined.isel(point=slice(0, end + 1))
        bifs, stop = [b for b in bifs if b["after"] < end] + [hopf[0]], "hopf"
    return joined.assign_attrs(parts[0].attrs | {"bifurcations": json.dumps(bifs),
                                                 "stop": stop})


def _switched_branch(orbits, problem, branch, point,
                     continuation_options: ContinuationOptions, algorithm: PseudoArclength,
                     *, k: int, progress: bool) -> list:
    """The other branches through the branch point `point` of `branch`, each
    continued away from it for `continuation_options.max_points` points, with its
    bifurcations, and cut where it repeats itself (`_repeats_itself`); attributes
    `switched_from_vd` and those of `_branch_dataset`.
    The step onto the other branch is Keller's (`switch_branch`, the kernel
    direction the followed branch does not take); where it does not converge (a
    symmetric ring, where the kernel has more directions), the orbits that
    deflation finds beside the branch point (`switch_by_deflation`), and where that
    finds none, Keller's step along each axis of the orbit's symmetry in the
    kernel (`_switch_along_axes`). Where none finds one, the failure instead: a
    dict of the branch point's v_d and the reason, which the followed branch keeps
    (`failed_switches`)."""
    try:
        starts = [switch_branch(problem, branch, point, algorithm=algorithm)]
    except RuntimeError as err:
        starts = (switch_by_deflation(problem, branch, point, algorithm=algorithm)
                  or _switch_along_axes(problem, branch, point, algorithm))
        if not starts:
            return [{"v_d": float(point.p), "reason": f"{err}; deflation beside it found no "
                     "other orbit, nor a step along an axis of its symmetry"}]
    out = []
    for new, tangent in starts:
        ds = _pieces_dataset(k, _through_sliding(new, algorithm, continuation_options,
                                                 tangent=tangent, progress=progress))
        ds = _repeats_itself(orbits, new.params, ds)
        out.append(ds.assign_attrs(switched_from_vd=float(point.p),
                                   stop=json.dumps({"away": ds.attrs["stop"]})))
    return out


def _switch_along_axes(problem, branch, point, algorithm: PseudoArclength) -> list:
    """Keller's step (`switch_branch`) from the branch point `point` along each axis
    of the critical plane that a symmetry of its orbit fixes
    (`symmetric_directions`, with the orbit's isotropy subgroup, `isotropy`), to
    both sides: the (problem, tangent) of each that converges. Tried where the
    kernel direction and deflation beside the point fail: the whole ring of 20's
    branch point with a double multiplier +1. Empty for an orbit with no
    symmetry."""
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


def _passes_through(orbits, params: ChainParams, orbit, branch: xr.Dataset,
                    tol: float = 1e-6, *, images: bool = True) -> int | None:
    """The first point i of `branch` such that the branch passes through the
    periodic orbit `orbit` (at `params.v_d`) between points i and i + 1, or None.
    Where the branch crosses v_d between two points whose interpolated period and
    amplitudes sorted by size (a signature no rotation or reflection changes) lie
    within 0.1 of the orbit's, the orbit of the branch at v_d is shot from the
    interpolated point; the same orbit when its signature agrees within `tol` (both
    are solved to Newton's tolerance). `orbit`: anything with `amplitudes`, shape
    (n_osc,), and `period`. With `images` False, only `orbit` itself counts, not
    its images under the ring's rotations and reflections: the shot's state and
    period must then agree with `orbit.y0` and `orbit.period` within `tol` (both
    with the branch's phase condition)."""
    v0 = float(params.v_d)
    signature = np.append(np.sort(np.asarray(orbit.amplitudes)), float(orbit.period))
    v, u = branch["v_d"].values, branch["u"].values
    known = np.column_stack([np.sort(branch["amplitudes"].values, axis=1),
                             branch["period"].values])
    for i in np.flatnonzero((v[:-1] - v0) * (v[1:] - v0) <= 0):
        w = 0.0 if v[i + 1] == v[i] else (v0 - v[i]) / (v[i + 1] - v[i])
        if np.max(np.abs(known[i] + w * (known[i + 1] - known[i]) - signature)) > 0.1:
            continue
        y, period = unpack(jnp.asarray(u[i] + w * (u[i + 1] - u[i])))
        shot = orbits.shoot(params, y, period, int(branch.attrs["phase_oscillator"]))
        found = np.append(np.sort(np.asarray(shot.amplitudes)), float(shot.period))
        same = images or np.max(np.abs(np.asarray(pack(shot.y0, shot.period))
                                       - np.asarray(pack(orbit.y0, orbit.period)))) < tol
        if bool(shot.converged) and np.max(np.abs(found - signature)) < tol and same:
            return int(i)
    return None
