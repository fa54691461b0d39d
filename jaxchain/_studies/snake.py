"""The snake: branches of the chain's localized periodic states over the belt speed,
with their Floquet stability and bifurcations, started from direct simulation."""

from __future__ import annotations

from typing import TYPE_CHECKING, NamedTuple

import dataclasses
import json
from pathlib import Path

import jax.numpy as jnp
import numpy as np

from .._engine.progress import tqdm
from .._bifurcation.bifurcations import locate_bifurcations
from .._bifurcation.branch_switching import (switch_branch, switch_by_deflation,
                                              symmetric_directions)
from .._bifurcation.continuation import ContinuationOptions, PseudoArclength, continuation
from .._bifurcation.deflation import chain_symmetries, distinct_orbits
from .._bifurcation.past_sliding import past_sliding_start
from .._bifurcation.shooting import pack, unpack
from .._sweeps.ensemble import ensemble
from .._engine.options import SimulationOptions
from .._engine.observers.crossings import downward_crossings
from .._physics.chain import Graph
from .._physics.initial import GivenState, OutOfPhaseExcitation, centre_site, excited_block
from .._physics.params import chain_or_default, ChainParams, with_parameter
from .._physics.record import chain_record
from .._engine.simulate import simulate
from .._engine.solver.registry import DEFAULT_SOLVER
from .snake_orbits import snake_orbits
from .snake_pool import Followers
from .._sweeps.result_store import read_dataset, write_dataset
from .._errors import ValidationError
from .._engine.status import Status

if TYPE_CHECKING:  # heavy: imported where they are used
    import xarray as xr

def default_sites(n_osc: int) -> tuple[int, ...]:
    """The branches of `localized_branches` by default: eq. (8) with 1, 2, 4, ...
    oscillators excited (the powers of two up to half the chain) and the whole
    chain; 1, 2, 4, 8 and 20 on the paper's ring (its Figs. 4 and 8)."""
    sites = [2**i for i in range(n_osc.bit_length()) if 2**i <= n_osc // 2]
    return tuple(sites + [n_osc])

#: The one-site starts of a lattice by the number of their neighbours: a corner (2),
#: the middle of the top edge (3) and the centre (4; `centre_site`).
LATTICE_STARTS = ("corner", "edge", "interior")


def default_starts(graph: Graph) -> tuple:
    """The starts of `localized_branches` by default: `default_sites` on a line or
    any links, the one-site states of `LATTICE_STARTS` on a lattice."""
    return LATTICE_STARTS if graph.kind == "lattice" else default_sites(graph.n_osc)


def start_site(graph: Graph, name: str) -> int:
    """The oscillator (0-based) of a named one-site start: "corner" (0), "edge" (row
    0, column cols//2), "interior" (`centre_site`) on a lattice, or "site:N" (any
    graph).

    **Raises:** `ValidationError` for another name, a lattice name on another graph,
    or an oscillator outside the chain."""
    if name.startswith("site:"):
        try:
            n = int(name[5:])
        except ValueError:
            n = -1
        if not 0 <= n < graph.n_osc:
            raise ValidationError(f"start {name!r}: the oscillator must be in "
                                  f"0..{graph.n_osc - 1}")
        return n
    if name not in LATTICE_STARTS or graph.kind != "lattice":
        raise ValidationError(f"start {name!r}: give a number of excited oscillators, "
                              f"site:N, or on a lattice one of {', '.join(LATTICE_STARTS)}")
    cols = graph.shape[1]
    return {"corner": 0, "edge": cols // 2, "interior": centre_site(graph)}[name]


def start_mask(graph: Graph, start) -> np.ndarray:
    """The oscillators a start excites: k of them in the block or patch of
    `excited_block` for a number k, one for a named start (`start_site`)."""
    if isinstance(start, str):
        mask = np.zeros(graph.n_osc, dtype=bool)
        mask[start_site(graph, start)] = True
        return mask
    return excited_block(graph.n_osc, int(start), graph)


def _start_label(start) -> str:
    return start if isinstance(start, str) else f"k={start}"


def check_starts(graph: Graph, starts) -> tuple:
    """The starts (`default_starts` if None), each a number in 1..n_osc or a name of
    `start_site`.

    **Raises:** `ValidationError` naming a bad start."""
    starts = default_starts(graph) if starts is None else tuple(
        s if isinstance(s, str) else int(s) for s in starts)
    if not starts:
        raise ValidationError("sites must name at least one start")
    for s in starts:
        if isinstance(s, str):
            start_site(graph, s)
        elif not 1 <= s <= graph.n_osc:
            raise ValidationError(f"sites must be in 1..n_osc = {graph.n_osc}, got {starts}")
    return starts


#: The starting simulations: a chain of 20 settles slowly (the paper removes
#: 10^4 time units of transient); after 2500 the four- and eight-site states of
#: eq. (8) at v_d = 1.5 are not yet periodic to the shooting tolerance.
SNAKE_START = SimulationOptions(t_end=12_000.0, transient=11_500.0)

#: Where the simulated state of a start is not periodic at the snake's v_d (a torus
#: born at a Neimark-Sacker point of the branch, or an irregular state), eq. (8) is
#: simulated again at these offsets from it, in turn: on the ring of 20 the nine-site
#: state is periodic at 1.6 and the ten-site state at 1.4, neither at 1.5.
RETRY_VD = (-0.1, 0.1)

#: Where shooting from the first turning point of a start's simulated state fails,
#: it is tried from this many more, those where the state comes back closest after
#: one turn first (`_recurrences`): the ring of 20's nineteen-site state of eq. (8)
#: at v_d = 1.6 lingers near an unstable orbit (multiplier 1.02) without settling.
RECURRENCES = 4

#: A start that gives no orbit with as many sites on the HALC as it excites, at v_d
#: or at the offsets `RETRY_VD`, and whose eq. (8) state a symmetry of the chain
#: fixes (`isotropy`), is simulated again inside that symmetry's fixed subspace
#: (`symmetric_state`), projected back onto it every this many time units: the ring
#: of 20's nineteen-site orbit at v_d = 1.6 is unstable only across it (multiplier
#: 1.0206 a period of 6.23: rounding grows by less than a factor 1.5 within one).
SYMMETRIC_CHUNK = 100.0

#: Continuation of each branch: far enough each way (150 points) to pass its folds.
SNAKE_CONTINUATION = ContinuationOptions(ds=0.02, ds_max=0.1, p_min=1.0, p_max=2.2,
                                         max_points=150)


def _downward_crossings(orbits, params: ChainParams, y, horizon: float = 40.0
                        ) -> tuple[np.ndarray, np.ndarray, list]:
    """The flow of the engine of `orbits` (`snake_orbits`) from `y`, sampled every
    1e-3 over `horizon`: (times, states, and for each oscillator the sample indices
    where x_n' passes from + to -, the intervals of `downward_crossings`)."""
    ts = np.linspace(0.0, horizon, int(round(horizon * 1000)) + 1)
    ys = orbits.samples(params, y, ts)
    mask, _ = downward_crossings(ts, ys[:, 0], ys[:, 1], np.ones(ts.size, dtype=bool))
    mask = np.asarray(mask)
    return ts, ys, [np.flatnonzero(mask[:, n]) for n in range(mask.shape[1])]


def _turning_point(orbits, params: ChainParams, y: np.ndarray, oscillator: int
                   ) -> tuple[np.ndarray, float] | None:
    """A state where x_n' passes from + to - (n = `oscillator`), and the time to the
    next such crossing (`_downward_crossings` on the engine of `orbits`)."""
    guesses = _recurrences(orbits, params, y, oscillator)
    return guesses[0] if guesses else None


def _recurrences(orbits, params: ChainParams, y: np.ndarray, oscillator: int,
                 horizon: float = 40.0) -> list[tuple[np.ndarray, float]]:
    """The states where x_n' passes from + to - (n = `oscillator`) over `horizon`
    from `y`, each with the time to the next such crossing: the first, then the
    others by how closely the state returns there (max-norm), closest first. A
    close recurrence lies near a periodic orbit, unstable ones included, that
    the flow passes (Auerbach et al. 1987, Phys. Rev. Lett. 58, 2387)."""
    ts, ys, down = _downward_crossings(orbits, params, y, horizon)
    return _closest_returns(ts, ys, down[oscillator])


def _closest_returns(ts, ys, down) -> list[tuple[np.ndarray, float]]:
    """`_recurrences` from the samples (ts, ys) and the indices `down` of one
    oscillator's turning points (`_downward_crossings`)."""
    gaps = [float(np.max(np.abs(ys[b] - ys[a]))) for a, b in zip(down[1:-1], down[2:])]
    order = [0] + [1 + i for i in np.argsort(gaps, kind="stable")]
    return [(ys[down[i]], float(ts[down[i + 1]] - ts[down[i]])) for i in order
            if i + 1 < down.size]


def start_orbits(params: ChainParams, sites=None, *, options: SimulationOptions = SNAKE_START,
                 engine: str = "smoothed", shooting=None, solver=DEFAULT_SOLVER, eps=None,
                 retry: tuple = RETRY_VD, progress: bool = False):
    """Periodic localized states of the chain at `params.v_d`, refined by shooting
    from direct simulation: eq. (8) with k oscillators excited (`excited_block`),
    integrated over `options`, then a turning point of the oscillator of largest
    amplitude (the phase condition's oscillator) and the time to the next one as the
    guesses of `periodic_orbit` (where it fails, from the `RECURRENCES` states of
    closest return, `_recurrences`). Where that state is not periodic (or steady
    sliding, or the simulation fails), or where its orbit has not as many sites on
    the HALC as the start excites, eq. (8) is simulated again at `params.v_d` + each
    offset of `retry` in turn, and the first periodic orbit that keeps the start's
    number of sites (else the first periodic one, else the orbit at `params.v_d`)
    is kept at its own v_d. A start that still has no orbit with its own number of
    sites, and whose eq. (8) state a symmetry of the chain fixes (`isotropy`), is
    simulated inside the fixed subspace of those symmetries (`symmetric_state`) at
    `params.v_d`, then at each offset, and shot from there: the first orbit with
    its own number of sites replaces the one it had.

    **Arguments:**

    - `params`: the chain; `params.v_d` is the belt speed of the start.
    - `sites`: the starts: numbers of excited oscillators, each in 1..n_osc, or
        named one-site starts (`start_site`: "corner", "edge", "interior" on a
        lattice, "site:N"); `default_starts` by default.
    - `options`: `SimulationOptions` of the simulations.
    - `engine`: "smoothed" (eq. (5) with tanh(v_rel/eps)) or "exact" (the stick/slip
        switch model) for the simulations and shooting.
    - `shooting`: `ShootingOptions` (smoothed) or `ExactShooting` (exact); its
        `phase_oscillator` is replaced (`SNAKE_SHOOTING`, `EXACT_SNAKE_SHOOTING` by
        default).
    - `solver`: the smoothed engine's solver of the simulations (`SOLVERS`;
        shooting has its own).
    - `eps`: the smoothed engine's smoothing velocity of tanh(v_rel/eps), a finite
        number > 0, shape (), dimensionless (a fraction of x_0 omega_n), of the
        simulations and of shooting; `DEFAULT_EPS` when None. None for the exact
        engine.
    - `retry`: offsets of v_d, dimensionless, tried in turn for the starts that
        give no periodic orbit at `params.v_d`, or one with another number of
        sites on the HALC than they excite (`RETRY_VD`; () for none).
    - `progress`: progress bars.

    **Returns:**

    A dict k -> (`PeriodicOrbit` or `ExactOrbit`, or None; the simulation's n_HALC,
    energy and `v_d`; why it failed or None). The orbit lies at `orbit.params.v_d`.
    A start fails when at every belt speed tried the simulated state is not
    periodic (irregular: shooting does not converge) or never turns.

    **Raises:**

    `ValidationError` for a k outside 1..n_osc, eps <= 0, eps given to the exact
    engine or shooting options of the other engine.
    """
    orbits = snake_orbits(engine, shooting, eps, solver, params)
    return _start_orbits(orbits, params, sites, options, progress, tuple(retry))


def _start_orbits(orbits, params: ChainParams, sites, options: SimulationOptions,
                  progress: bool, retry: tuple = RETRY_VD) -> dict:
    """`start_orbits` on the engine of `orbits` (`snake_orbits`): at `params.v_d`,
    then for each start that gives no periodic orbit there, or one that has lost
    the pattern it excites (another number of sites on the HALC: the ring of 20's
    nineteen-site start ends on the whole ring at 1.5), at the belt speeds
    `params.v_d` + `retry` in turn (`_shoot_starts`). The first orbit found with
    as many sites on the HALC as the start excites is kept, else the first orbit
    found; at its own v_d (`orbit.params`), its simulation record with `v_d`. A
    start that fails at every one keeps the reason of `params.v_d`. A start with no
    orbit of its own number of sites by then is tried inside the fixed subspace of
    its symmetries at the same speeds (`_symmetric_start`)."""
    sites = check_starts(params.graph, sites)
    v0 = float(params.v_d)
    vds = [v0 + d for d in retry]
    out = _shoot_starts(orbits, params, sites, [v0], options, progress)[v0]
    for k, (_, sim, _) in out.items():
        sim["v_d"] = v0

    def keeps(k, orbit) -> bool:
        return orbit is not None and int(orbit.n_halc) == int(start_mask(params.graph, k).sum())

    again_k = [k for k in sites if not keeps(k, out[k][0])]
    if again_k and retry:
        again = _shoot_starts(orbits, params, again_k, vds, options, progress)
        for k in again_k:
            tried = [again[v][k] + (v,) for v in vds]
            found = [(o, sim | {"v_d": v}, None) for o, sim, _, v in tried if o is not None]
            # an orbit that keeps the pattern; else, for a start with none, any orbit
            choice = [f for f in found if keeps(k, f[0])] or (
                found if out[k][0] is None else [])
            if choice:
                out[k] = choice[0]
            elif out[k][0] is None:
                out[k] = out[k][:2] + (out[k][2] + "; at v_d " + ", ".join(
                    f"{v:g}: {why}" for _, _, why, v in tried),)
    for k in [k for k in sites if not keeps(k, out[k][0])]:
        out[k] = _symmetric_start(orbits, params, k, [v0, *vds], options.t_end, out[k])
    return out


def _symmetric_start(orbits, params: ChainParams, k, vds: list, t_end: float, had: tuple
                     ) -> tuple:
    """The start k, which gave no orbit with its own number of sites, simulated
    inside the fixed subspace of its eq. (8) state's symmetries (`isotropy`,
    `_symmetric_orbit`) at each belt speed of `vds` in turn: the first orbit with
    the start's number of sites, with its record (`symmetric` True); else `had`
    (the reason of a start with no orbit extended)."""
    mask, whys = start_mask(params.graph, k), []

    def eq8(v):
        at = with_parameter(params, "v_d", v)
        return at, np.asarray(OutOfPhaseExcitation.eq8(mask)(at)).reshape(2, -1)

    perms = isotropy(*eq8(vds[0]))  # the same at every belt speed
    if len(perms) == 1:  # no symmetry: nothing to try
        return had
    for v in vds:
        at, start = eq8(v)
        orbit, why, m = _symmetric_orbit(orbits, at, start, perms, t_end)
        if orbit is not None and int(orbit.n_halc) == int(mask.sum()):
            return orbit, {"n_halc": int(orbit.n_halc), "energy": float(orbit.energy),
                           "phase_oscillator": m, "v_d": v, "symmetric": True}, None
        whys.append(f"{v:g}: " + (why or f"{int(orbit.n_halc)} sites on the HALC"))
    if had[0] is not None:
        return had
    return had[:2] + (had[2] + "; inside the fixed subspace of its symmetry, at v_d "
                      + ", ".join(whys),)


def _shoot_starts(orbits, params: ChainParams, sites: tuple, vds: list,
                  options: SimulationOptions, progress: bool) -> dict:
    """The starts `sites` simulated at each belt speed of `vds` (one ensemble) and
    refined by shooting: v_d -> k -> (the orbit or None, the simulation's n_HALC,
    energy and phase oscillator, why it failed or None)."""
    masks = np.stack([start_mask(params.graph, k) for k in sites])
    ics = OutOfPhaseExcitation(excited=jnp.asarray(masks),
                               velocity=jnp.zeros(len(sites)), base_sign=-1.0)
    ds = ensemble(params, vds, ics, engine=orbits.simulation(options, params),
                  progress=progress)
    out = {}
    for j, v in enumerate(vds):
        at, out[v] = with_parameter(params, "v_d", v), {}
        for i, k in enumerate(sites):
            amplitudes = ds["amplitudes"].values[j, i]
            sim = {"n_halc": int(ds["n_halc"].values[j, i]),
                   "energy": float(ds["energy"].values[j, i])}
            if int(ds["status"].values[j, i]) != Status.ok:
                out[v][k] = (None, sim, "the simulation failed")
                continue
            n = int(np.argmax(amplitudes))
            sim["phase_oscillator"] = n  # of the orbit's phase condition
            orbit, reason = _shoot_guesses(
                orbits, at, _recurrences(orbits, at, ds["y_final"].values[j, i], n), n)
            out[v][k] = (orbit, sim, reason)
    return out


def _symmetric_orbit(orbits, params: ChainParams, start, perms, t_end: float):
    """The start simulated inside the fixed subspace of `perms` (`symmetric_state`)
    and refined by shooting from its recurrences, projected onto it, with the
    oscillator of largest amplitude as the phase oscillator: (orbit or None, why
    none or None, that oscillator)."""
    y = symmetric_state(orbits, params, start, perms, t_end)
    if not np.all(np.isfinite(y)):
        return None, "the simulation failed", 0
    ts, ys, down = _downward_crossings(orbits, params, y)
    m = int(np.argmax(np.ptp(ys[:, 0], axis=0)))
    return (*_shoot_guesses(orbits, params, _closest_returns(ts, ys, down[m]), m, perms), m)


def _shoot_guesses(orbits, params: ChainParams, guesses: list, n: int, perms=None):
    """Shooting (`orbits.shoot`, phase oscillator n) from the first 1 + `RECURRENCES`
    of `guesses` (`_recurrences`) in turn, each first projected onto the fixed
    subspace of `perms` where given (`symmetric_state`): (the first converged orbit,
    None), or (None, why none)."""
    if not guesses:
        return None, "no turning point: steady sliding"
    for y, period in guesses[:1 + RECURRENCES]:
        orbit = orbits.shoot(params, y if perms is None else _projected(y, perms), period, n)
        if bool(orbit.converged):
            return orbit, None
    return None, (f"shooting did not converge (residual {float(orbit.residual):.2g}): the "
                  f"simulated state is not periodic")


def isotropy(params: ChainParams, y, atol: float = 1e-12) -> np.ndarray:
    """The symmetries of the chain (`chain_symmetries`: on a homogeneous ring its
    rotations and reflections) that map the state y, shape (2, n_osc), onto itself
    within `atol`: its isotropy subgroup, shape (s, n_osc), the identity first. For
    eq. (8) on the ring, an odd block of excited oscillators is fixed by the
    reflection about its centre; an even block by no symmetry (its signs
    alternate). A state solved by shooting keeps its symmetry only to Newton's
    tolerance: pass an `atol` above it."""
    y = np.asarray(y)
    perms = np.asarray(chain_symmetries(params))
    fixed = perms[[np.allclose(y[:, p], y, rtol=0.0, atol=atol) for p in perms]]
    return fixed[np.argsort([not np.array_equal(p, np.arange(y.shape[1])) for p in fixed],
                            kind="stable")]


def _projected(y, perms) -> np.ndarray:
    """The orthogonal projection of y, shape (2, n_osc), onto the states fixed by
    every permutation of `perms` (a group): the mean of its copies y[:, p]."""
    y = np.asarray(y)
    return np.mean([y[:, p] for p in perms], axis=0)


def symmetric_state(orbits, params: ChainParams, y, perms, t_end: float,
                    chunk: float = SYMMETRIC_CHUNK) -> np.ndarray:
    """The flow of the engine of `orbits` (`snake_orbits`) from y, shape (2, n_osc),
    over `t_end` (dimensionless time, eqs. (4)-(6)), projected back onto the fixed
    subspace of the group `perms` (`isotropy`) every `chunk`: the chain's
    equations commute with its symmetries, so that subspace is invariant, and the
    projection only removes the rounding errors that an instability across it
    would grow. A periodic orbit unstable only across the subspace is an attractor
    inside it (Golubitsky, Stewart and Schaeffer 1988, *Singularities and Groups in
    Bifurcation Theory* II, Ch. XIII, the fixed-point subspaces). Shape (2, n_osc);
    nan where the flow fails."""
    y = _projected(y, perms)
    for _ in range(int(np.ceil(t_end / chunk))):
        y = _projected(orbits.samples(params, y, np.array([0.0, chunk]))[-1], perms)
    return y


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
        attrs={"excited": k, "phase_oscillator": problem.residual.options.phase_oscillator,
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


def stable_ranges(branch: xr.Dataset) -> list[dict]:
    """The stable segments of a joined branch: their v_d ranges, each end the
    bifurcation located there (or the end of the computed branch), and for each
    end the index of its last stable point and of the first point beyond it
    (None at the end of the branch)."""
    stable = branch["stable"].values
    v = branch["v_d"].values
    bifs = json.loads(branch.attrs["bifurcations"])
    out = []
    i = 0
    while i < stable.size:
        if not stable[i]:
            i += 1
            continue
        j = i
        while j + 1 < stable.size and stable[j + 1]:
            j += 1
        ends = []
        for idx, other in ((i, i - 1), (j, j + 1)):
            # the bifurcation located between the two points (or at the branch's
            # end, beyond its last point), else an unlocated change
            between = [b for b in bifs if b["after"] == min(idx, other)]
            if not 0 <= other < stable.size:
                ends.append((between[0] if between else
                             {"type": "end of branch", "v_d": float(v[idx])}, idx, None))
                continue
            ends.append((between[0] if between else
                         {"type": "stability change", "v_d": float(0.5 * (v[idx] + v[other]))},
                         idx, other))
        ends.sort(key=lambda e: e[0]["v_d"])
        out.append({"v_d": [ends[0][0]["v_d"], ends[1][0]["v_d"]],
                    "ends": [e[0] for e in ends],
                    "points": [(e[1], e[2]) for e in ends],
                    "n_halc": int(np.bincount(branch["n_halc"].values[i:j + 1]).argmax())})
        i = j + 1
    return out


def _connections(branches: dict, tol: float = 1e-3) -> dict:
    """Which branches meet: two branches connect when a point of one matches a point
    of the other at the same belt speed (within `tol`), with the same period (within
    `tol`, relative) and the same amplitudes sorted by size (within 10 `tol`): a
    signature that no rotation or reflection of the chain changes. A branch whose
    energy falls below 1e-4, or that ends at a Hopf point, ends on steady sliding."""
    out = {k: [] for k in branches}
    keys = list(branches)
    for a in keys:
        hopf = any(b["type"] == "Hopf" for b in json.loads(branches[a].attrs["bifurcations"]))
        if hopf or float(branches[a]["energy"].min()) < 1e-4:
            out[a].append("steady sliding")
        for b in keys:
            if b == a:
                continue
            A, B = branches[a], branches[b]
            va, vb = A["v_d"].values, B["v_d"].values
            close = np.abs(va[:, None] - vb[None, :]) < tol
            period = np.abs(A["period"].values[:, None] / B["period"].values[None, :] - 1) < tol
            sa = np.sort(A["amplitudes"].values, axis=1)
            sb = np.sort(B["amplitudes"].values, axis=1)
            cand = np.argwhere(close & period)
            if any(np.max(np.abs(sa[i] - sb[j])) < 10 * tol for i, j in cand):
                out[a].append(b)
    return out


def _sites_connections(datasets: dict, links: dict, n_osc: int) -> list[dict]:
    """Whether the orbits with n and with n + 1 sites on the HALC connect, for n = 0
    ... n_osc - 1: the branches (labels of `datasets`, each with `n_halc` and
    `stable` at each point) are joined where they meet (`links`: label -> the
    labels it meets, `_connections` and the switched branches' parents) into
    connected sets, and n connects to n + 1 where one such set carries orbits with
    both numbers of sites (along one branch, through a sliding point, or across a
    point where two meet); `stable_connected` where one set carries stable orbits
    with both. One entry per n: sites [n, n + 1], the labels of the branches that
    carry each (`with_n`, `with_n_plus_1`), `connected`, `through` (each connected
    set that carries both, as sorted labels) and `stable_connected`."""
    parent = {label: label for label in datasets}

    def root(label):
        while parent[label] != label:
            label = parent[label]
        return label

    for a, met in links.items():
        for b in met:
            if a in parent and b in parent:
                parent[root(a)] = root(b)
    sets: dict = {}
    for label in datasets:
        sets.setdefault(root(label), []).append(label)
    on = {label: set(ds["n_halc"].values.astype(int).tolist())
          for label, ds in datasets.items()}
    stable = {label: set(ds["n_halc"].values[ds["stable"].values.astype(bool)].astype(int)
                         .tolist()) for label, ds in datasets.items()}
    out = []
    for n in range(n_osc):
        both = [sorted(ls) for ls in sets.values()
                if any(n in on[x] for x in ls) and any(n + 1 in on[x] for x in ls)]
        out.append({"sites": [n, n + 1],
                    "with_n": [x for x in datasets if n in on[x]],
                    "with_n_plus_1": [x for x in datasets if n + 1 in on[x]],
                    "connected": bool(both), "through": both,
                    "stable_connected": any(
                        any(n in stable[x] for x in ls) and any(n + 1 in stable[x] for x in ls)
                        for ls in sets.values())})
    return out


def _phase_lags(orbits, params: ChainParams, y, sites) -> np.ndarray | None:
    """The phase of each oscillator of `sites` relative to the first, in periods
    (0 to 1): from the first turning point (x_n' from + to -) of each
    (`_downward_crossings` on the engine of `orbits`)."""
    ts, _, down = _downward_crossings(orbits, params, y)
    if any(down[n].size < 2 for n in sites):
        return None
    first = np.asarray([ts[down[n][0]] for n in sites])
    period = float(ts[down[sites[0]][1]] - ts[down[sites[0]][0]])
    return np.mod((first - first[0]) / period, 1.0)


def _check_by_simulation(orbits, params: ChainParams, branch: xr.Dataset, segment: dict, *,
                         delta: float = 0.03, perturbation: float = 1e-3, seed: int = 0,
                         options: SimulationOptions = SimulationOptions(t_end=5000.0,
                                                                        transient=4500.0)
                         ) -> list[dict]:
    """Direct simulation (the engine of `orbits`, over `options`) just inside and
    just outside each end of a stable segment that a
    bifurcation ends, each from an orbit of the branch with its positions
    perturbed by `perturbation`:

    - inside: at v_d = end -+ `delta` (at most half the segment's length, so as
      to stay on it), from the segment's orbit nearest there;
    - outside a fold, a sliding point (past it the branch goes on without that
      stick phase, or ends), or a bifurcation at the end of the branch with no
      orbit beyond it (the state ceases to exist): at end +- `delta`, from the
      orbit nearest it;
    - outside a change of stability: on the unstable sheet beyond it, from its
      orbit where the perturbation grows to 100 within the horizon
      (`_unstable_point`; a weak instability needs |mu| to grow).

    The state persists when the simulation ends with the oscillators of the
    starting orbit on the HALC (amplitude above half the largest, and sticking in
    each period where the orbit's sites do: `on_halc`) and, among them,
    the same phase lags within 0.05 of a period (a symmetry-breaking instability
    keeps the sites and changes their phases); it is lost otherwise.

    **Returns:**

    One dict per end and side: v_d, start_v_d (the orbit started from), side
    ("inside"/"outside"), the sites of the orbit and of the simulation, the largest
    phase-lag difference, `persists`, `expected_growth` (outside a change of
    stability: |mu|^(t_end / T) of the starting orbit) and `agrees` (persists
    inside, lost outside), None where the perturbation times the expected growth
    stays below 1, too weak an instability for the horizon to decide.
    """
    rng = np.random.default_rng(seed)
    v = branch["v_d"].values
    stable = branch["stable"].values
    growth = (branch["critical_multiplier_abs"].values
              ** (options.t_end / branch["period"].values))
    out = []
    for end, (last, beyond) in zip(segment["ends"], segment["points"]):
        if end["type"] == "end of branch":
            continue
        outward = np.sign(end["v_d"] - v[last]) or 1.0
        # inside, but not past the segment's other end: at most half its length in
        reach = min(delta, 0.5 * abs(segment["v_d"][1] - segment["v_d"][0]))
        inside = _segment_point(v, stable, last, end["v_d"] - outward * reach)
        sides = [("inside", end["v_d"] - outward * reach, inside, None)]
        if end["type"] in ("fold", "sliding", "Hopf") or beyond is None:
            # beyond a fold, a sliding point (the branch turns there onto orbits
            # without that stick phase, or ends), a Hopf point or a bifurcation that
            # ends the branch, the state does not exist
            sides.append(("outside", end["v_d"] + outward * delta, last, None))
        else:
            sides.append(("outside",) + _unstable_point(v, stable, growth, beyond, last, end,
                                                        delta, perturbation))
        for side, vd, start, expected in sides:
            y_orbit, _ = unpack(jnp.asarray(branch["u"].values[start]))
            a = branch["amplitudes"].values[start]
            sites = np.flatnonzero(a > 0.5 * a.max())
            lags = _phase_lags(orbits, with_parameter(params, "v_d", float(v[start])), y_orbit,
                               sites)
            y0 = np.asarray(y_orbit).copy()
            y0[0] += perturbation * rng.standard_normal(y0.shape[1])
            p = with_parameter(params, "v_d", float(vd))
            obs = simulate(p, GivenState(jnp.asarray(y0)), engine=orbits.simulation(options, p))
            amp = np.asarray(obs.amplitudes)
            # where the orbit's sites stick, the simulation's must too: a chain that
            # decays to steady sliding keeps the orbit's pattern in its vanishing
            # oscillation, on no HALC
            halc = np.asarray(obs.on_halc) | (int(branch["n_halc"].values[start]) == 0)
            sim_sites = np.flatnonzero((amp > 0.5 * amp.max()) & halc)
            lag_difference = None
            if np.array_equal(sites, sim_sites) and lags is not None:
                sim_lags = _phase_lags(orbits, p, obs.y_final, sites)
                if sim_lags is not None:
                    d = np.mod(sim_lags - lags, 1.0)
                    lag_difference = float(np.max(np.minimum(d, 1 - d)))
            persists = lag_difference is not None and lag_difference < 0.05
            resolved = expected is None or perturbation * expected > 1.0
            out.append({"end": end["type"], "end_v_d": end["v_d"], "side": side,
                        "v_d": float(vd), "start_v_d": float(v[start]),
                        "sites_orbit": sites.tolist(), "sites_simulation": sim_sites.tolist(),
                        "phase_lag_difference": lag_difference, "persists": persists,
                        "expected_growth": expected,
                        "agrees": (persists == (side == "inside")) if resolved else None})
    return out


def _segment_point(v, stable, last, target) -> int:
    """The stable point of the segment that ends at `last` nearest to v_d = `target`."""
    same = [last]
    for step in (-1, 1):
        k = last + step
        while 0 <= k < v.size and stable[k]:
            same.append(k)
            k += step
    return min(same, key=lambda k: abs(v[k] - target))


def _unstable_point(v, stable, growth, beyond, last, end, delta, perturbation
                    ) -> tuple[float, int, float | None]:
    """(v_d, starting point, expected growth) of the simulation outside a change of
    stability. Its sheet is the unstable part of the branch beyond the change, as
    far as it runs on in v_d (up to a fold). On it: the first point at least
    `delta` from the end where a perturbation of size `perturbation` grows to 100
    within the horizon, else the farthest such point; the simulation starts from
    that orbit. If none grows enough and the sheet turns at a fold within `delta`,
    v_d = end + `delta` outward, past the fold, where the state does not exist
    (expected growth None); otherwise the point of largest growth (undecided)."""
    step = beyond - last
    outward = np.sign(v[beyond] - v[last]) or 1.0
    sheet = []
    k = beyond
    while 0 <= k < v.size and not stable[k] and (
            not sheet or (v[k] - v[sheet[-1]]) * outward > 0):
        sheet.append(k)
        k += step
    strong = [k for k in sheet if perturbation * growth[k] >= 100.0]
    far = [k for k in strong if abs(v[k] - end["v_d"]) >= delta]
    if far or strong:
        k = (far or strong[::-1])[0]
        return float(v[k]), k, float(growth[k])
    turns = 0 <= k < v.size and not stable[k]
    if turns and abs(v[sheet[-1]] - end["v_d"]) < delta:
        return float(end["v_d"] + outward * delta), last, None
    k = max(sheet, key=lambda k: growth[k])
    return float(v[k]), k, float(growth[k])


def _multiplier_accuracy(orbits, params: ChainParams, branch: xr.Dataset, points) -> dict:
    """How accurate the branch's Floquet multipliers are: at the given points, the
    multipliers again from the same orbits with the flow's tolerances divided by
    `orbits.check_factor` (100 tighter on the smoothed engine; 100 looser on the
    exact one, already near rounding, where the difference bounds the error); the
    difference estimates the error at the branch's tolerances.

    **Returns:**

    A dict: `points`, `rtol` (the two), the largest difference of the critical
    multiplier (`critical_difference`) and of its modulus (`modulus_difference`),
    and the largest |trivial multiplier - 1| at each tolerance.
    """
    factor = orbits.check_factor
    v = branch["v_d"].values
    critical, modulus, trivial = [], [], ([], [])
    for i in sorted(set(int(i) for i in points)):
        p = with_parameter(params, "v_d", float(v[i]))
        got = []
        for f, errors in zip((1.0, factor), trivial):
            values, index = orbits.multipliers(p, branch["u"].values[i], f)
            errors.append(abs(values[int(index)] - 1))
            got.append(np.delete(values, int(index)))
        first = got[0][0]  # the critical multiplier, and its match at the tight tolerance
        second = got[1][np.argmin(np.abs(got[1] - first))]
        critical.append(abs(first - second))
        modulus.append(abs(abs(first) - abs(second)))
    return {"points": len(critical), "rtol": [orbits.rtol(), orbits.rtol(factor)],
            "critical_difference": float(max(critical, default=np.nan)),
            "modulus_difference": float(max(modulus, default=np.nan)),
            "trivial_error": [float(max(e, default=np.nan)) for e in trivial]}


def localized_branches(params: ChainParams | None = None, sites=None, *,
                       engine: str = "smoothed", shooting=None,
                       continuation_options: ContinuationOptions = SNAKE_CONTINUATION,
                       start_options: SimulationOptions = SNAKE_START,
                       solver=DEFAULT_SOLVER, eps=None, switch: bool = True,
                       deflate: int = 0,
                       simulation_check: bool = True,
                       out: Path | None = None, progress: bool = False,
                       workers: int = 1) -> dict:
    """The snake: each localized periodic state that simulation finds at
    `params.v_d` (eq. (8) with k excited, for k in `sites`), refined by shooting,
    continued over v_d both ways by pseudo-arclength through its folds, with its
    Floquet multipliers, bifurcations (`locate_bifurcations`), stable ranges, the
    branches it meets and, optionally, direct simulation just inside and outside each
    end of each stable range.

    **Arguments:**

    - `params`: the chain (any chain of `ChainParams`); `params.v_d` is where the
        states are found (1.5 by default, inside the paper's bistable range).
    - `sites`: the starts: numbers of excited oscillators (eq. (8)'s block or a
        graph's patch) or named one-site starts (`start_site`); `default_starts`
        by default (the corner, edge and interior one-site states on a lattice).
    - `engine`: "smoothed" (eq. (5) with tanh(v_rel/eps)) or "exact" (the stick/slip
        switch model: exact shooting, exact Floquet multipliers, simulations on
        the exact engine) for every orbit, branch and simulation.
    - `shooting`: `ShootingOptions` (smoothed) or `ExactShooting` (exact) of every
        orbit (`SNAKE_SHOOTING`, `EXACT_SNAKE_SHOOTING` by default).
    - `continuation_options`: `ContinuationOptions` (direction is set both ways).
    - `start_options`: `SimulationOptions` of the starting simulations.
    - `solver`: the smoothed engine's solver of the simulations, the starts and the
        checks (`SOLVERS`); shooting has its own (`shooting.solver`).
    - `eps`: the smoothed engine's smoothing velocity of tanh(v_rel/eps) (None:
        `DEFAULT_EPS`; None for the exact engine), a finite number > 0,
        shape (), dimensionless (a fraction of x_0 omega_n): that of the smoothed
        engine of every simulation (`Smoothed.eps`) and of every orbit, branch and
        multiplier; `DEFAULT_EPS` by default. Stored branches are read back only
        for an equal eps.
    - `switch`: at each branch point of a branch, switch onto the other branch
        through it and follow that too (`switch_branch`: the kernel direction that
        the followed branch does not take; where that fails, as at the branch
        points of a symmetric ring, every orbit that `switch_by_deflation` finds
        beside it; labelled "k=<k> switched <j>").
    - `deflate`: at `params.v_d`, up to this many further periodic orbits from the
        eq. (8) state of each start by deflation (`distinct_orbits`), every orbit
        found so far deflated; each is followed as a branch of its own, labelled
        "k=<k> deflated <j>", unless it lies on a branch already followed (a branch
        with folds crosses v_d more than once): that one is reported in
        `deflated_on_followed` (0: none).
    - `simulation_check`: check every stable range by direct simulation.
    - `out`: a folder: each branch is stored there as `branch_k<k>.nc` (or
        `branch_<name>.nc`) with the key
        of its settings (`write_dataset`) as it finishes, and read back on a later
        call with equal settings (resume); the starts not stored are computed, and
        with `deflate` their deflation deflates the stored starts' orbits too, as
        the whole run would.
    - `progress`: progress bars.
    - `workers`: the number of processes that follow the starts' branches side by
        side (1: one after another, in this process). The branches are the same
        either way (each is the same computation), and so is what is stored;
        with more, a deflated orbit's branch may be followed and then dropped,
        where it lies on a branch followed before it.

    **Returns:**

    A dict with `summary` (JSON-ready: `branches`, a list of objects with `label`,
    `excited`, `sites`, `stable_ranges`, `bifurcations`, `connects_to`, ...;
    `not_periodic`, the starts without a periodic orbit and why;
    `deflated_on_followed`, the deflated orbits found on a branch already followed,
    each with its `start`, `energy`, `n_halc` and the branch it lies `on`; and
    `sites_connections`, for n = 0 ... N - 1 whether the orbits with n and n + 1
    sites on the HALC connect, stable ones included, `_sites_connections`) and
    `datasets` (label -> the branch's `xarray.Dataset`).

    **Raises:**

    `ValidationError` for bad sites, options or eps, an unknown engine, eps given
    to the exact engine or shooting options of the other engine.
    """
    params, sites, orbits = _check_branches(params, sites, engine, shooting, solver, eps)
    if not (isinstance(deflate, int) and deflate >= 0):
        raise ValidationError(f"deflate must be a whole number >= 0, got {deflate!r}")
    if not (isinstance(workers, int) and workers >= 1):
        raise ValidationError(f"workers must be a whole number >= 1, got {workers!r}")
    run = _run_branches(orbits, params, sites, continuation_options, start_options, switch,
                        deflate, simulation_check, out, progress, workers)
    return _branches_summary(*run, params.n_osc)


def _check_branches(params: ChainParams | None, sites, engine, shooting, solver, eps
                    ) -> tuple:
    """The chain (the paper's ring where None), the starts (`check_starts`) and the
    orbits of the engine (`snake_orbits`, which checks eps and the options)."""
    params = chain_or_default(params)
    orbits = snake_orbits(engine, shooting, eps, solver, params)
    return params, check_starts(params.graph, sites), orbits


def _run_branches(orbits, params: ChainParams, sites: tuple, continuation_options,
                  start_options, switch, deflate, simulation_check, out, progress,
                  workers: int = 1) -> tuple:
    """The branches (`_find_branches`), then the checks of their stable ranges
    (`_stable_range_checks`): (datasets, starts, failed starts, deflated orbits on
    branches already followed, checks)."""
    datasets, starts, failed, repeated = _find_branches(
        orbits, params, sites, continuation_options, start_options, switch, deflate, out,
        progress, workers)
    checks = _stable_range_checks(orbits, params, datasets, simulation_check,
                                  progress)
    return datasets, starts, failed, repeated, checks


def _find_branches(orbits, params: ChainParams, sites: tuple, continuation_options,
                   start_options, switch, deflate, out, progress, workers: int = 1
                   ) -> tuple[dict, dict, dict, list]:
    """The branch of each start, with `deflate` the branches of the further orbits
    that deflation finds from its eq. (8) state (`_deflated_orbits`; one on a branch
    already followed is reported, `_on_followed_branch`, not followed again), and
    with `switch` the branches switched onto at their branch points: read back from
    `out` where stored with the same settings, else started by simulation and
    shooting (`start_orbits`), continued (`_follow_start`) and stored. Returns
    (label -> branch dataset, start -> the simulation's n_HALC and energy, start ->
    why it has no periodic orbit, the deflated orbits on branches already followed
    from starts without a branch of their own; those of the others are their
    branch's attribute `deflated_repeats`). A start without a branch of its own is
    stored as a record of why (`_read_branches`), so that a resumed run does not
    compute it again."""

    datasets, starts, failed, repeated, known = {}, {}, {}, [], []
    settings = {"chain": chain_record(params), **orbits.settings(),
                "continuation": continuation_options, "start": start_options,
                "switch": bool(switch), "deflate": int(deflate),
                "sliding_passes": SLIDING_PASSES, "branch_method": BRANCH_METHOD,
                "retry_vd": list(RETRY_VD), "recurrences": RECURRENCES,
                "symmetric_chunk": SYMMETRIC_CHUNK}
    paths = {k: None if out is None else Path(out) / (
        f"branch_{k}.nc" if isinstance(k, str) else f"branch_k{k}.nc").replace(":", "")
        for k in sites}
    todo = []
    for k in sites:
        stored = None if out is None else _read_branches(paths[k], k, _start_label(k),
                                                         settings)
        if stored is None:
            todo.append(k)
            continue
        known += _stored_orbits(stored, float(params.v_d))
        record = stored[_start_label(k)]
        if "no_branch" in record.attrs:  # a start without a branch of its own
            del stored[_start_label(k)]
            failed[k] = record.attrs["no_branch"]
            starts[k] = json.loads(record.attrs["simulation"])
            repeated += json.loads(record.attrs["deflated_repeats"])
        datasets |= stored
    if not todo:
        return datasets, starts, failed, repeated
    lo, hi = continuation_options.p_min, continuation_options.p_max
    retry = tuple(d for d in RETRY_VD if lo < float(params.v_d) + d < hi)
    found = _start_orbits(orbits, params, todo, start_options, progress, retry)
    # a resumed run deflates the stored starts' orbits too, as the run it resumes did
    deflated = _deflated_orbits(orbits, params, found, deflate, stored=known
                                ) if deflate else {}
    with Followers(workers) as pool:
        # every branch asked for at once, each from its start (a deflated orbit's may
        # go unused, where it lies on a branch followed before it); with one worker
        # each is computed when the loop below asks for it, as the sequential run did
        follow = dict(orbits=orbits, continuation_options=continuation_options,
                      switch=switch, progress=progress and workers <= 1)
        jobs = {}
        for k, (orbit, sim, _) in found.items():
            mask = start_mask(params.graph, k)
            if orbit is not None:
                jobs[k] = pool.submit(_follow_start, orbit, sim["phase_oscillator"],
                                      mask, **follow)
            for i, (o, m, _) in enumerate(deflated.get(k, [])):
                if o is not None:
                    jobs[k, i] = pool.submit(_follow_start, o, m, mask, **follow)
        _take_branches(orbits, params, found, deflated, jobs, out, paths, settings,
                       (datasets, starts, failed, repeated))
    return datasets, starts, failed, repeated


def _take_branches(orbits, params: ChainParams, found: dict, deflated: dict, jobs: dict,
                   out, paths: dict, settings: dict, into: tuple) -> None:
    """The branches of `jobs` (`_find_branches`), in the order of the starts: each
    start's own, then those of its deflated orbits not on a branch followed before
    (`_on_followed_branch`), labelled and stored, into (datasets, starts, failed,
    repeated)."""
    import xarray as xr

    datasets, starts, failed, repeated = into
    for k, (orbit, sim, reason) in found.items():
        starts[k] = sim
        own, mask = _start_label(k), start_mask(params.graph, k)
        # a start whose simulated state is not periodic keeps its reason, and the
        # orbits that deflation finds from its eq. (8) state are followed still
        if orbit is None:
            failed[k] = reason
        mine = {} if orbit is None else _labelled(own, orbit, mask, jobs[k].result())
        if isinstance(mine, str):
            starts[k], failed[k], mine = sim, mine, {}
        followed, repeats, j = {}, [], 0
        for i, (o, m, _) in enumerate(deflated.get(k, [])):
            on = None if o is None else _on_followed_branch(orbits, params, o,
                                                           datasets | mine | followed)
            if on is not None:
                repeats.append({"start": own, "energy": float(o.energy),
                                "n_halc": int(o.n_halc), "on": on})
            if o is None or on is not None:
                continue
            j += 1
            label = f"{own} deflated {j}"
            branches = _labelled(label, o, mask, jobs[k, i].result())
            if isinstance(branches, str):
                starts[label], failed[label] = sim, branches
                continue
            _store_branches(out, _numbered(paths[k], "deflated", j), branches, settings, k)
            followed |= branches
        # every orbit this start gave deflation (`_deflated_orbits`), for a resumed run
        known = {"deflation_known": json.dumps([np.asarray(u, dtype=float).tolist() for u in (
            [] if orbit is None or float(orbit.params.v_d) != float(params.v_d)
            else [pack(orbit.y0, orbit.period)]) + [u for _, _, u in deflated.get(k, [])]])}
        if own in mine:  # stored last: its attributes count the deflated branches
            mine[own] = mine[own].assign_attrs(deflated=j, deflated_repeats=json.dumps(repeats),
                                               start_symmetric=int(bool(sim.get("symmetric"))),
                                               **known)
            _store_branches(out, paths[k], mine, settings, k)
        else:
            repeated += repeats
            _store_branches(out, paths[k], {own: xr.Dataset(attrs={
                "no_branch": failed[k], "simulation": json.dumps(sim), "switched": 0,
                "deflated": j, "deflated_repeats": json.dumps(repeats), **known})},
                settings, k)
        datasets |= mine | followed


def _follow_start(start, phase_oscillator: int, mask, *, orbits, continuation_options,
                  switch, progress) -> tuple | str:
    """The branch through the periodic orbit `start` (`_follow_branch`) and the
    branches switched onto from it, (branch, [switched, ...]), or why its
    continuation failed. Run in a worker process where `workers` > 1."""
    try:
        return _follow_branch(orbits, start, phase_oscillator, continuation_options,
                              k=int(mask.sum()), switch=switch, progress=progress)
    except (ValueError, RuntimeError) as err:  # flagged; the other branches go on
        return f"continuation failed: {err}"


def _labelled(label: str, start, mask, followed: tuple | str) -> dict | str:
    """The branches of `_follow_start` from `start`, labelled `label` and "<label>
    switched <j>" (label -> dataset), or why its continuation failed."""
    if isinstance(followed, str):
        return followed
    ds, switched = followed
    first = ds.assign_attrs(start_vd=float(start.params.v_d), start_energy=float(start.energy),
                            start_n_halc=int(start.n_halc), switched=len(switched), deflated=0,
                            deflated_repeats="[]")
    branches = [first] + [sw.assign_attrs(start_vd=sw.attrs["switched_from_vd"],
                                          start_energy=float(sw["energy"].values[0]),
                                          start_n_halc=int(sw["n_halc"].values[0]))
                          for sw in switched]
    return {label if j == 0 else f"{label} switched {j}":
            b.assign_attrs(start=label, start_sites=np.flatnonzero(mask).tolist())
            for j, b in enumerate(branches)}


def _store_branches(out, path: Path | None, branches: dict, settings: dict, k) -> None:
    """Write a start's branch and those switched onto from it (`_follow_start`) to
    `path` and beside it, each with the key of its settings."""
    if out is None:
        return
    Path(out).mkdir(parents=True, exist_ok=True)
    label = next(iter(branches))
    for j, b in enumerate(branches.values()):
        write_dataset(b, _numbered(path, "switched", j), "snake branch", k=k, label=label,
                      switched=j, **settings)


def _on_followed_branch(orbits, params: ChainParams, orbit, branches: dict) -> str | None:
    """The label of a branch in `branches` that passes through the periodic orbit
    `orbit` at `params.v_d` (`_passes_through`), or None."""
    return next((label for label, ds in branches.items()
                 if _passes_through(orbits, params, orbit, ds) is not None), None)


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


def _stored_orbits(stored: dict, v_d: float) -> list:
    """The orbits at `v_d` that one start gave deflation in the run that stored its
    branches, `stored` (`_read_branches`), as shooting unknowns (x, x', T): its
    own orbit and every solution deflation found from it, as deflation had them
    (the record's `deflation_known`). Files written before that attribute give the
    first point of the start's own and deflated branches instead (not a switched
    branch, nor one started at a neighbouring v_d)."""
    record = next(iter(stored.values()))
    if "deflation_known" in record.attrs:
        return [jnp.asarray(u) for u in json.loads(record.attrs["deflation_known"])]
    out = []
    for label, ds in stored.items():
        if " switched " in label or "no_branch" in ds.attrs or float(
                ds.attrs["start_vd"]) != v_d:
            continue
        i = int(np.argmin(np.abs(ds["v_d"].values - v_d)))
        if float(ds["v_d"].values[i]) == v_d:
            out.append(jnp.asarray(ds["u"].values[i]))
    return out


def _deflated_orbits(orbits, params: ChainParams, found: dict, count: int,
                     stored: list = ()) -> dict:
    """Further periodic orbits at `params.v_d` by deflation (`distinct_orbits`, Farrell,
    Birkisson and Funke 2015): from the eq. (8) state of each start k (T = 2 pi),
    those whose simulated state is not periodic included, with every orbit found so
    far deflated (the starts' own, those of earlier k, their symmetric copies,
    steady sliding), up to `count` each; each refined by
    shooting with the phase condition on its oscillator of largest amplitude.
    `stored`: the orbits of the starts that a resumed run read back
    (`_stored_orbits`), deflated too, so that resuming finds what the whole run
    would. Returns k -> [(orbit, its phase oscillator, the deflation's solution u),
    ...], the orbit None where shooting from u does not converge."""
    # the starts' orbits at params.v_d; one found at a neighbouring v_d
    # (`RETRY_VD`) is not a solution here, and its start is treated as not periodic
    here = {k: (o if o is not None and float(o.params.v_d) == float(params.v_d) else None,
                sim, why) for k, (o, sim, why) in found.items()}
    known = [pack(o.y0, o.period) for o, _, _ in here.values() if o is not None]
    known += list(stored)
    # the shooting problem of a start whose state is not periodic: another start's,
    # with the phase condition on its own oscillator (only the residual is used)
    template = next((o for o, _, _ in here.values() if o is not None), None)
    # slots for every orbit that can be found: one compiled solve for all starts
    capacity = len(known) + count * len(here)
    out = {}
    for k, (orbit, sim, _) in here.items():
        n = (sim or {}).get("phase_oscillator")
        if template is None or n is None:
            continue
        problem = orbits.problem(template if orbit is None else orbit, n)
        y0 = jnp.asarray(OutOfPhaseExcitation.eq8(start_mask(params.graph, k))(params))
        start = pack(y0.at[1, n].set(0.0), 2 * np.pi)
        new = distinct_orbits(problem, start, known, count=count, capacity=capacity)
        known += new
        out[k] = []
        for u in new:
            y, period = unpack(u)
            shot = orbits.shoot(params, y, period, n)
            m = int(np.argmax(np.asarray(shot.amplitudes)))
            if m != n:  # the phase condition on the oscillator that vibrates most
                guess = _turning_point(orbits, params, np.asarray(y), m)
                shot = None if guess is None else orbits.shoot(params, guess[0], guess[1], m)
            out[k].append((shot if shot is not None and bool(shot.converged) else None,
                           m, u))
    return out


def _numbered(path: Path | None, what: str, j: int) -> Path | None:
    """The file of the j-th branch of kind `what` (switched, deflated) beside the
    branch stored at `path` (j = 0: that branch)."""
    return path if path is None or j == 0 else path.with_name(f"{path.stem}_{what}{j}.nc")


def _read_branches(path: Path, k, label: str, settings: dict) -> dict | None:
    """The stored branch `label` of start k, the branches switched onto from it and
    the deflated branches of the start with theirs (label -> dataset), or None if
    any of them is missing or was made with other settings. A start without a
    branch of its own has a record instead of its branch: a dataset without
    variables, its attributes `no_branch` (why), `simulation` (JSON: the start's
    n_HALC and energy) and `deflated_repeats`."""
    first = read_dataset(path, "snake branch", k=k, label=label, switched=0, **settings)
    if first is None:
        return None
    out = {label: first}
    for j in range(1, int(first.attrs.get("switched", 0)) + 1):
        out[f"{label} switched {j}"] = read_dataset(_numbered(path, "switched", j),
                                                    "snake branch", k=k, label=label,
                                                    switched=j, **settings)
    if any(ds is None for ds in out.values()):
        return None
    for j in range(1, int(first.attrs.get("deflated", 0)) + 1):
        deflated = _read_branches(_numbered(path, "deflated", j), k, f"{label} deflated {j}",
                                  settings)
        if deflated is None:
            return None
        out |= deflated
    return out


def _stable_range_checks(orbits, params: ChainParams, datasets: dict,
                         simulation_check: bool, progress: bool) -> dict:
    """For each branch (by label): its stable ranges (`stable_ranges`), the accuracy
    of its multipliers at their ends and at its start (`_multiplier_accuracy`), and
    with `simulation_check` direct simulation at each end (`_check_by_simulation`)."""
    out = {}
    bar = tqdm(total=len(datasets), desc="simulation check", disable=not (progress and
                                                                           simulation_check))
    for label, ds in datasets.items():
        ranges = stable_ranges(ds)
        ends = [i for r in ranges for pair in r["points"] for i in pair if i is not None]
        start = int(np.argmin(np.abs(ds["v_d"].values - ds.attrs["start_vd"])))
        out[label] = {"ranges": ranges, "multiplier_accuracy": _multiplier_accuracy(
            orbits, params, ds, ends + [start])}
        if simulation_check:
            out[label]["simulation_check"] = [
                c for r in ranges for c in _check_by_simulation(orbits, params, ds, r)]
        bar.update()
    bar.close()
    return out


def _branches_summary(datasets: dict, starts: dict, failed: dict, repeated: list,
                      checks: dict, n_osc: int) -> dict:
    """The result of `localized_branches`: its JSON-ready summary, one entry per
    branch with what `_stable_range_checks` found, the deflated orbits that lie on
    branches already followed, and the datasets."""
    links = _connections(datasets)
    for label, ds in datasets.items():  # a switched branch meets its own at the branch point
        parent = ds.attrs["start"] if "switched" in label else None
        if parent in datasets:
            links[label].append(parent)
            links[parent].append(label)
    links = {label: list(dict.fromkeys(met)) for label, met in links.items()}
    branches = []
    for label, ds in datasets.items():
        ranges = checks[label]["ranges"]
        entry = {"label": label, "excited": int(ds.attrs["excited"]),
                 "start_sites": [int(i) for i in np.atleast_1d(ds.attrs.get(
                     "start_sites", []))],
                 "sites": (int(np.bincount(ds["n_halc"].values[ds["stable"].values]).argmax())
                           if ds["stable"].values.any() else None),
                 "stable_ranges": [r["v_d"] for r in ranges],
                 "stable_range_ends": [r["ends"] for r in ranges],
                 "bifurcations": json.loads(ds.attrs["bifurcations"]),
                 "connects_to": links[label],
                 "v_d_computed": [float(ds["v_d"].min()), float(ds["v_d"].max())],
                 "points": int(ds.sizes["point"]),
                 "stop": json.loads(ds.attrs["stop"]),
                 "start": {"v_d": ds.attrs["start_vd"], "energy": ds.attrs["start_energy"],
                           "n_halc": ds.attrs["start_n_halc"],
                           "symmetric": bool(ds.attrs.get("start_symmetric", 0))},
                 "switched_from_vd": ds.attrs.get("switched_from_vd"),
                 "failed_switches": json.loads(ds.attrs.get("failed_switches", "[]")),
                 "largest_trivial_multiplier_error": float(
                     ds["trivial_multiplier_error"].max())}
        entry |= {k: v for k, v in checks[label].items() if k != "ranges"}
        branches.append(entry)
    repeated = repeated + [r for ds in datasets.values()
                           for r in json.loads(ds.attrs.get("deflated_repeats", "[]"))]
    summary = {"branches": branches,
               "not_periodic": [{"excited": k, "reason": r, "simulation": starts[k]}
                                for k, r in failed.items()],
               "deflated_on_followed": repeated,
               "sites_connections": _sites_connections(datasets, links, n_osc)}
    return {"summary": summary, "datasets": datasets}

