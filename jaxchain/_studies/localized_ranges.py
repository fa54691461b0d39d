"""The one-site localized state's stable range in v_d over stiffness mistuning draws:
its two ends (where the largest non-trivial Floquet multiplier leaves the unit
circle: a Neimark-Sacker point, a fold of limit cycles, a period doubling) as
distributions, by harmonic balance vmapped over the draws.

The tuned ring's branch is followed once with the one driver (`follow_branch`),
which locates its ends. Every draw then starts at the same belt speed from the
tuned orbit (Newton's method through the draw's ring at half its mistuning) and
marches along its own branch both ways by pseudo-arclength steps (Keller 1977: a
secant prediction, corrected on the hyperplane normal to it by the chord method
with the Jacobian assembled from harmonic balance's own, `_crossings`), all draws
at once; the step halves where a correction fails. At each point the largest
non-trivial multiplier (one monodromy integration from the orbit's start). An end
where that multiplier leaves the unit circle is located by regula falsi (Illinois)
on the segment between the last stable and the first unstable point. A fold
whose branch turns at a sharp corner (the smoothed grazing of the stick phase,
where even short steps fail) is located by bisection on v_d: the furthest v_d to
which Newton's method continues the last orbit.

Mistuning draws as `mistuned_lanes` (common random numbers across the strengths);
the state sits at oscillator `site` of every draw, whose neighbours' detuning moves
its range (`docs/anderson.md`)."""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import lineax as lx
import numpy as np

from .._bifurcation.branches import FollowedBranch, follow_branch
from .._bifurcation.continuation import ContinuationOptions, PseudoArclength
from .._bifurcation.harmonic_balance import HarmonicBalance
from .._bifurcation.orbit_method import (critical_multiplier, deflated_multipliers,
                                          flow_direction)
from .._bifurcation.periodic_orbit import periodic_orbit
from .._engine.compat import checks_as_nan
from .._checks import check_count
from .._errors import ValidationError
from .._physics.params import ChainParams
from .._physics.record import chain_record
from .magnification import mistuned_lanes

#: The tuned branch's continuation: small steps, so that its points resolve both ends.
TUNED_CONTINUATION = ContinuationOptions(ds=0.01, ds_max=0.05, p_min=1.0, p_max=2.2,
                                         max_points=80)
#: The arclength step of each draw's march from the start to its two ends (the
#: norm of the harmonic-balance unknowns and v_d together), and the steps' budget.
STEP = 0.08
MAX_STEPS = 40
#: Regula falsi steps of an end met as a multiplier leaving the unit circle.
REFINEMENTS = 4
#: Bisections of an end met as a fold's corner, within FOLD_WIDTH in v_d past the
#: last orbit before it: a resolution of FOLD_WIDTH / 2^BISECTIONS (4.7e-4; the
#: midpoint reported, within 2.3e-4), a tenth of the 5e-3 that the check by
#: shooting allows (each bisection costs a Newton solve of every lane at its fold).
BISECTIONS = 6
FOLD_WIDTH = 0.03
#: The version of the draws' procedure, in each stored part's key: a part computed
#: by another is computed again.
PROCEDURE = 5
#: The multipliers' integration tolerances (rtol, atol): the sign of |mu| - 1 needs
#: far less than shooting's 1e-10.
MULTIPLIER_TOLERANCES = (1e-6, 1e-8)
#: A step shortened to this fraction of the step without passing stops its lane.
SHORTEST = 8
#: The chord method's iteration budget per crossing.
CHORD_STEPS = 30
#: A correction that moves the orbit further than this has jumped to another branch.
JUMP = 0.2
#: The lane counts of the draws' compiled programs: a call on fewer lanes (those
#: still marching, refining or bisecting) runs on the next count up.
BUCKETS = (1, 4, 16, 32, 48)


@dataclasses.dataclass(frozen=True)
class BranchRange:
    """A one-site branch followed by the driver (`FollowedBranch`) and its stable
    segment through the start: `low`, `high` (dimensionless v_d), each end's
    bifurcation `low_kind`, `high_kind` ("Neimark-Sacker", "fold", ...) and the
    index of the point before it, `low_after`, `high_after`."""

    branch: FollowedBranch
    low: float
    low_kind: str
    low_after: int
    high: float
    high_kind: str
    high_after: int


def branch_range(params: ChainParams, method, *, site: int = 0,
                 options: ContinuationOptions = TUNED_CONTINUATION, store=None
                 ) -> BranchRange:
    """The one-site state at oscillator `site` of the chain `params` (found by
    simulating eq. (8) and shooting at `params.v_d`, `localized_orbit`, on the
    smoothed model at the method's eps), moved to `method` (a `Shooting` or a
    `HarmonicBalance`), its branch followed both ways by `follow_branch`, and the
    stable segment through the start with the bifurcations located at its ends.
    `store`: a netCDF file where the branch is kept and read back for equal
    arguments (`follow_branch`).

    **Raises:** `RuntimeError` where the state is not found at `params.v_d`, or is
    not stable there, or its stable segment has an end without a located
    bifurcation."""
    from .._engine.engines import Smoothed
    from .mistuning.edges import localized_orbit

    shot, _ = localized_orbit(params, site, engine=Smoothed(eps=method.engine.eps))
    if shot is None:
        raise RuntimeError(f"no periodic one-site state at oscillator {site} at v_d "
                           f"{float(params.v_d):g}: start from a v_d inside its range")
    method = method.with_phase_oscillator(site)
    orbit = periodic_orbit(shot.params, shot, method)
    branch = follow_branch(orbit, method, options, store=store)
    start = int(np.argmin(np.abs(branch.p - float(params.v_d))))
    stable = branch.stable
    if not stable[start]:
        raise RuntimeError(f"the one-site state is not stable at v_d {float(params.v_d):g}")
    first, last = start, start
    while first > 0 and stable[first - 1]:
        first -= 1
    while last + 1 < stable.size and stable[last + 1]:
        last += 1
    ends = []
    for after in (first - 1, last):
        found = [b for b in branch.bifurcations if b.after == after]
        if after < 0 or not found:
            raise RuntimeError(f"the one-site branch's stable segment through v_d "
                               f"{float(params.v_d):g} has an end without a located "
                               f"bifurcation (after point {after})")
        ends.append((float(found[0].p), found[0].kind, after))
    return BranchRange(branch, *ends[0], *ends[1])


@checks_as_nan
@eqx.filter_jit
def _crossings(method: HarmonicBalance, chains: ChainParams, predicted, base, normal,
               algorithm: PseudoArclength, newton: bool):
    """Each lane's crossing of its hyperplane {z: normal . (z - base) = 0}: the
    chord method (Newton's with the matrix of the first iterate kept: one
    factorization per crossing, then back-substitutions), or Newton's method where
    `newton` (near a fold, where the chord's reach is too short), on the harmonic
    balance and the hyperplane together (Keller's corrector, as `PseudoArclength`'s,
    to its tolerance), from `predicted` moved onto the hyperplane. The matrix is
    assembled from the residual's own (`HarmonicBalance.jacobian`) with the column
    of v_d (one forward-mode product) and factored by LU (lineax; on this bordered
    matrix GMRES preconditioned by the oscillator blocks measured no faster).
    Vmapped over the lanes of `chains`, `predicted`, `base`, `normal`, each shape
    (lanes, n + 1) with z = (u, v_d): (z, converged)."""
    from .._physics.params import with_parameter

    solver = lx.LU()

    def one(params, z0, b, t):
        def balance(u, v):
            return method._balance(u, with_parameter(params, "v_d", v))

        def factored(z):
            u, v = z[:-1], z[-1]
            column = jax.jvp(lambda v: balance(u, v), (v,), (jnp.ones_like(v),))[1]
            operator = lx.MatrixLinearOperator(jnp.concatenate([
                jnp.concatenate([method.jacobian(u, with_parameter(params, "v_d", v)),
                                 column[:, None]], axis=1), t[None]]))
            return operator, solver.init(operator, {})

        start = z0 + t * (t @ (b - z0))
        first = factored(start)

        def step(carry):
            z, k, _ = carry
            operator, state = factored(z) if newton else first
            residual = jnp.concatenate([balance(z[:-1], z[-1]), (t @ (z - b))[None]])
            dz = lx.linear_solve(operator, residual, solver, state=state, throw=False).value
            return z - dz, k + 1, jnp.max(jnp.abs(dz) / (1 + jnp.abs(z)))

        def going(carry):
            _, k, change = carry
            return (k < (algorithm.newton_steps if newton else CHORD_STEPS)) & (
                change > algorithm.newton_tol)

        z, _, change = jax.lax.while_loop(going, step, (start, 0, jnp.asarray(jnp.inf)))
        return z, (change <= algorithm.newton_tol) & jnp.all(jnp.isfinite(z))

    return jax.vmap(one)(chains, predicted, base, normal)


@checks_as_nan
@eqx.filter_jit
def _critical(engine, chains: ChainParams, z, method: HarmonicBalance):
    """The largest non-trivial multiplier of each lane's orbit z = (u, v_d): its
    monodromy matrix by one integration of `engine` over the period from the
    orbit's start (as `HarmonicBalance(floquet="monodromy")`, at the engine's own
    tolerances), deflated of the trivial multiplier."""
    from .._physics.params import with_parameter

    def one(params, z):
        params = with_parameter(params, "v_d", z[-1])
        y0, period = method.orbit(z[:-1])
        shape = y0.shape
        monodromy = jax.jacfwd(lambda y: jnp.ravel(engine.flow(
            params, jnp.reshape(y, shape), period)))(jnp.ravel(y0))
        mu, trivial = deflated_multipliers(monodromy, flow_direction(engine, params, y0))
        return critical_multiplier(mu, trivial)

    return jax.vmap(one)(chains, z)


@dataclasses.dataclass(frozen=True)
class _Draws:
    """The lanes of one group: the harmonic balance, the stacked chains (`lanes` of
    them), the engine of the multipliers' integration and the corrector's
    tolerance and budget."""

    method: HarmonicBalance
    chains: ChainParams
    engine: object
    algorithm: PseudoArclength

    def _on(self, where, compute, *arrays):
        """`compute(draws, *arrays)` on the lanes where `where` holds only (all lanes
        where it is None), gathered and padded with copies of the first to the next
        of `BUCKETS` (so that a few programs serve every count): no lane idle in a
        call waits on the others. Returns (the chosen lanes' indices, their outputs),
        or None where `where` holds for no lane (no call)."""
        lanes = np.shape(arrays[0])[0]
        chosen = np.arange(lanes) if where is None else np.flatnonzero(where)
        if chosen.size == 0:
            return None
        size = min([b for b in BUCKETS if b >= chosen.size] + [lanes])
        index = np.concatenate([chosen, np.full(size - chosen.size, chosen[0])])
        draws = dataclasses.replace(self, chains=jax.tree_util.tree_map(
            lambda a: a[index], self.chains))
        outputs = compute(draws, *(jnp.asarray(np.asarray(a)[index]) for a in arrays))
        return chosen, tuple(np.asarray(o)[:chosen.size] for o in outputs)

    def corrected(self, predicted, base, normal, newton: bool = False, where=None
                  ) -> tuple[np.ndarray, np.ndarray]:
        """`_crossings` of the lanes where `where` holds (all where None): (z, ok),
        z the prediction and ok False on the others."""
        z, ok = np.array(predicted, dtype=float), np.zeros(np.shape(predicted)[0], bool)
        done = self._on(where, lambda d, *a: _crossings(d.method, d.chains, *a, d.algorithm,
                                                        newton), predicted, base, normal)
        if done is not None:
            chosen, (z_chosen, ok_chosen) = done
            z[chosen], ok[chosen] = z_chosen, ok_chosen
        return z, ok

    def critical(self, z: np.ndarray, where=None) -> np.ndarray:
        """The largest non-trivial multiplier of each lane's orbit z (complex) where
        `where` holds (all lanes where None), NaN on the others."""
        out = np.full(np.shape(z)[0], np.nan, dtype=complex)
        done = self._on(where, lambda d, z: (_critical(d.engine, d.chains, z, d.method),), z)
        if done is not None:
            out[done[0]] = done[1][0]
        return out


def _stability_end(d: _Draws, z0: np.ndarray, t0: np.ndarray, step: float,
                   max_steps: int, refinements: int
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each lane's end of stability along its branch from the stable orbits z0 =
    (u, v_d), shape (lanes, n + 1), in the direction t0: pseudo-arclength steps of
    `step` (the prediction along the secant of the last step, corrected on the
    hyperplane normal to it) until the largest non-trivial |multiplier| exceeds 1
    (a Neimark-Sacker point, a fold or a period doubling: whichever ends the
    range), then regula falsi (Illinois) on the segment between the last stable
    orbit and the first unstable one, each trial orbit corrected on the hyperplane
    normal to the segment through its point there.

    A lane whose step fails `log2 SHORTEST` times in a row (a fold's sharp corner:
    the smoothed grazing of the stick phase) stops there.

    **Returns:** (v_d of the end, found, the critical multiplier just past it),
    shape (lanes,), and each stopped lane's last orbit (NaN for the others), shape
    (lanes, n + 1); an end is not found
    where the start is not stable, a lane stopped, or no end was met within
    `max_steps` steps.
    """
    lanes = z0.shape[0]

    def corrected(base, normal, where):
        return d.corrected(base, base, normal, where=where)

    z, t = z0, np.broadcast_to(t0, z0.shape)
    c = d.critical(z)
    g = np.abs(c) - 1.0
    ok = g <= 0  # a stable start
    done = np.zeros(lanes, dtype=bool)  # crossed into instability
    stuck = np.zeros(lanes, dtype=bool)  # no step passes: at a fold's corner
    h = np.full(lanes, float(step))
    a, b, ga, gb = z.copy(), z.copy(), g.copy(), g.copy()
    cb = c.copy()  # the critical multiplier at b: the kind of the end
    for _ in range(max_steps):
        predicted = z + h[:, None] * t
        active = ok & ~done & ~stuck
        z_new, converged = corrected(predicted, t, active)
        # a correction far from its prediction jumped to another branch: a failure
        converged = converged & (np.linalg.norm(z_new - predicted, axis=1) <= h)
        h = np.where(active & ~converged, h / 2, h)  # a failed step is retried shorter
        stuck |= active & (h < step / SHORTEST)
        # a failed correction's iterate may be far from any orbit, where the
        # multipliers' integration would take its whole step budget
        z_new = np.where(converged[:, None], z_new, z)
        moves = active & converged
        c_new = d.critical(z_new, moves)
        g_new = np.abs(c_new) - 1.0
        crossed = moves & (g_new > 0)
        a, ga = np.where(crossed[:, None], z, a), np.where(crossed, g, ga)
        b, gb = np.where(crossed[:, None], z_new, b), np.where(crossed, g_new, gb)
        cb = np.where(crossed, c_new, cb)
        done |= crossed
        moves &= ~crossed
        moved = z_new - z
        length = np.linalg.norm(moved, axis=1, keepdims=True)
        t = np.where(moves[:, None], moved / np.where(length > 0, length, 1.0), t)
        z, g = np.where(moves[:, None], z_new, z), np.where(moves, g_new, g)
        h = np.where(moves, np.minimum(1.5 * h, step), h)
        if not np.any(ok & ~done & ~stuck):
            break
    found = ok & done
    a0, b0 = a.copy(), b.copy()  # the segment, fixed: trial points a0 + w (b0 - a0)
    normal = (b0 - a0) / np.where(found, np.linalg.norm(b0 - a0, axis=1), 1.0)[:, None]
    lo, hi, side = np.zeros(lanes), np.ones(lanes), np.zeros(lanes)
    refining = found.copy()
    for _ in range(refinements):
        span = np.where(refining, gb - ga, 1.0)
        w = np.where(refining, lo - ga * (hi - lo) / span, 0.0)  # the secant root
        trial = a0 + w[:, None] * (b0 - a0)
        zw, converged = corrected(trial, normal, refining)
        if np.any(refining & ~converged):  # the chord's reach is short near a fold
            z_newton, by_newton = d.corrected(trial, trial, normal, newton=True,
                                              where=refining & ~converged)
            zw = np.where((~converged & by_newton)[:, None], z_newton, zw)
            converged = converged | by_newton
        # a lane whose trial fails keeps its bracket: its end is interpolated there
        refining = refining & converged
        zw = np.where(refining[:, None], zw, a)
        cw = d.critical(zw, refining)
        gw = np.abs(cw) - 1.0
        stable = gw <= 0
        # Illinois: the end kept twice in a row has its value halved
        gb = np.where(refining & stable & (side > 0), gb / 2, gb)
        ga = np.where(refining & ~stable & (side < 0), ga / 2, ga)
        upper, lower = refining & stable, refining & ~stable
        lo, ga, a = (np.where(upper, w, lo), np.where(upper, gw, ga),
                     np.where(upper[:, None], zw, a))
        hi, gb, b = (np.where(lower, w, hi), np.where(lower, gw, gb),
                     np.where(lower[:, None], zw, b))
        cb = np.where(lower, cw, cb)
        side = np.where(refining, np.where(stable, 1.0, -1.0), side)
    w = ga / np.where(found, ga - gb, -1.0)  # the root between the last stable and unstable
    end = a[:, -1] + w * (b[:, -1] - a[:, -1])
    return (np.where(found, end, np.nan), found, np.where(found, cb, np.nan),
            np.where((ok & stuck)[:, None], z, np.nan))


def _last_orbit(d: _Draws, z: np.ndarray, width: float, bisections: int
                ) -> tuple[np.ndarray, np.ndarray]:
    """The fold beyond each lane's orbit z = (u, v_d) (NaN lanes are skipped): the
    furthest v_d to which its orbit continues, by bisection on v_d within `width`
    of it (above for width > 0, below for width < 0), each trial corrected at its
    v_d from the last orbit found (Newton's method on the hyperplane v_d =
    const). A fold is where the branch stops: at a sharp corner every continuation
    that can reach it finds it. Returns (v_d, found), shape (lanes,)."""
    lanes, n = z.shape
    normal = np.broadcast_to(np.eye(n)[-1], (lanes, n))
    found = np.all(np.isfinite(z), axis=1)
    lo = np.where(found[:, None], z, 0.0)
    lo[:, -1] = np.where(found, z[:, -1], 1.0)
    top = hi = lo[:, -1] + width
    for _ in range(bisections):
        v = 0.5 * (lo[:, -1] + hi)
        trial = np.concatenate([lo[:, :-1], v[:, None]], axis=1)
        zv, converged = d.corrected(trial, trial, normal, newton=True, where=found)
        passes = converged & (np.linalg.norm(zv - trial, axis=1) <= JUMP)
        lo = np.where(passes[:, None], zv, lo)
        hi = np.where(passes, hi, v)
    found &= hi != top  # some trial failed: the fold lies within the width
    return np.where(found, 0.5 * (lo[:, -1] + hi), np.nan), found


#: The kinds of an end of the stable range, by the multiplier that leaves the unit
#: circle there: +1 (a fold of limit cycles), -1 (period doubling), a complex pair
#: (Neimark-Sacker); a fold's sharp corner (the smoothed grazing of the stick phase),
#: where the march stops, is a fold too.
KINDS = ("fold", "period doubling", "Neimark-Sacker")


def _kind(multiplier: np.ndarray) -> np.ndarray:
    angle = np.abs(np.angle(multiplier))
    return np.where(angle < 1e-3, KINDS[0], np.where(angle > np.pi - 1e-3, KINDS[1], KINDS[2]))


def _ends(d: _Draws, z_start: np.ndarray, tangent: np.ndarray, v0: float, tuned
          ) -> dict:
    """Both ends of each lane's stable range (this module's docstring), from the
    tuned start z_start moved to each lane's orbit at v0, `tangent` pointing up in
    v_d: a dict of arrays over the lanes: low, high, low_kind, high_kind, found.
    `tuned`: the tuned ring's stiffness, which the homotopy of the start moves
    from."""
    lanes, n = z_start.shape
    # each lane's orbit at v0 by Newton's method, from the tuned ring's through the
    # lane's ring at half its mistuning (a homotopy: the tuned orbit is too far from
    # a strongly mistuned ring's for Newton's method alone)
    at_v0 = np.broadcast_to(np.eye(n)[-1], (lanes, n))
    half = dataclasses.replace(d, chains=eqx.tree_at(
        lambda c: c.stiffness, d.chains, tuned + 0.5 * (d.chains.stiffness - tuned)))
    z_half, ok = half.corrected(z_start, z_start, at_v0, newton=True)
    z0, converged = d.corrected(z_half, z_start, at_v0, newton=True)
    ok = ok & converged
    z0 = np.where(ok[:, None], z0, z_start)
    out = {"found": ok}
    for name, sign in (("low", -1.0), ("high", 1.0)):
        end, found, multiplier, stuck = _stability_end(d, z0, sign * tangent, STEP, MAX_STEPS,
                                                       REFINEMENTS)
        kind = np.where(found, _kind(multiplier), "")
        if np.any(np.isfinite(stuck[:, -1])):
            fold, at_fold = _last_orbit(d, stuck, sign * FOLD_WIDTH, BISECTIONS)
            end, found = np.where(at_fold, fold, end), found | at_fold
            kind = np.where(at_fold, KINDS[0], kind)
        out[name], out[f"{name}_kind"] = np.where(found & ok, end, np.nan), kind
        out["found"] = out["found"] & found
    return out


def _checked(params: ChainParams, sigmas, draws: int, lanes: int, site: int):
    if np.ndim(params.stiffness) != 0:
        raise ValidationError("the localized-ranges study needs a tuned chain (one "
                              "stiffness): it draws the mistuning itself")
    if params.forcing is not None:
        raise ValidationError("the localized-ranges study follows self-excited orbits: "
                              "give a chain without forcing")
    if any(not (np.isfinite(s) and s >= 0) for s in sigmas) or not len(sigmas):
        raise ValidationError(f"sigmas must be finite and >= 0, got {list(sigmas)!r}")
    check_count("draws", draws)
    check_count("lanes", lanes)
    if not (isinstance(site, (int, np.integer)) and 0 <= site < params.n_osc):
        raise ValidationError(f"site must be an oscillator of the chain, 0..{params.n_osc - 1}, "
                              f"got {site!r}")


def localized_ranges(params: ChainParams, sigmas, draws: int, method: HarmonicBalance, *,
                     site: int = 0, lanes: int = 64, workers: int = 1, progress: bool = False,
                     store=None):
    """The one-site localized state's stable range in v_d over stiffness mistuning
    draws and strengths, by harmonic balance vmapped over the draws (this module's
    docstring).

    **Arguments:**

    - `params`: the tuned ring (one stiffness), its `v_d` a belt speed inside the
        one-site state's stable range (the paper's 1.5), where every draw starts.
    - `sigmas`: the mistuning strengths (standard deviations of the ground
        stiffness deviations delta_n, >= 0).
    - `draws`: mistuned rings per strength (>= 1), `mistuned_lanes`.
    - `method`: the `HarmonicBalance` of every orbit (eps, H, M; its
        `linear_solver` serves the tuned branch, the draws' corrector factors by
        LU); its phase condition is moved to `site`.
    - `site`: the oscillator (0-based) on the HALC.
    - `lanes`: rings solved together (`jax.vmap`), a group.
    - `workers`: processes that compute the groups side by side (`Followers`, one
        thread each: on a CPU, one per core; 1 computes them here, one after the
        other). The ends agree with those of one process to the corrector's
        tolerance and the ends' resolutions.
    - `progress`: a progress bar.
    - `store`: a folder where each sigma's part is written as it finishes and read
        back where every setting that produced it matches: a killed study resumes.

    **Returns:** an `xarray.Dataset` over `sigma` and `draw`: `low`, `high` (the
    range's ends in v_d), `low_kind`, `high_kind` (`KINDS`; "" where not found),
    `found`; attributes: the tuned ring's range by the driver (`tuned_low`,
    `tuned_high` and their kinds) and by the draws' own procedure
    (`tuned_low_lanes`, `tuned_high_lanes`), the chain, the method, `site` and the
    wall time. Dimensionless (eqs. (4)-(6)).

    **Raises:** `ValidationError` for a mistuned or forced chain, a negative sigma,
    a bad count or site; `RuntimeError` where the tuned ring's one-site state is
    not found at `params.v_d` or its stable range is not bounded (`branch_range`).
    """
    import xarray as xr
    from tqdm.auto import tqdm

    from .pool import Followers
    from .response import method_settings

    _checked(params, sigmas, draws, lanes, site)
    check_count("workers", workers)
    began = time.perf_counter()
    method = method.with_phase_oscillator(site)
    if store is not None:
        Path(store).mkdir(parents=True, exist_ok=True)
    tuned = branch_range(params, method, site=site,
                         store=None if store is None else Path(store) / "tuned_branch.nc")
    bar = tqdm(total=len(sigmas) * draws, disable=not progress, unit="draw")
    with Followers(workers, one_thread=True) as pool:
        # every sigma's groups are submitted before any is awaited: the workers
        # stay busy across the strengths
        pending = [_part(params, float(sigma), draws, method, tuned, site, lanes, pool, store)
                   for sigma in sigmas]
        parts = [finish(bar) for finish in pending]
    bar.close()
    dims = ("sigma", "draw")
    names = ("low", "high", "low_kind", "high_kind", "found")
    return xr.Dataset(
        {k: (dims, np.stack([p[k].values for p in parts])) for k in names},
        coords={"sigma": np.asarray(sigmas, dtype=float),
                "sigma_over_eta_c": ("sigma", np.asarray(sigmas) / float(params.eta_c)),
                "draw": np.arange(draws)},
        attrs=chain_record(params) | method_settings(method) | {
            "site": site, "v_start": float(params.v_d),
            "tuned_low": tuned.low, "tuned_low_kind": tuned.low_kind,
            "tuned_high": tuned.high, "tuned_high_kind": tuned.high_kind,
            "tuned_low_lanes": float(parts[0].attrs["tuned_low_lanes"]),
            "tuned_high_lanes": float(parts[0].attrs["tuned_high_lanes"]),
            "wall_time_s": time.perf_counter() - began,
            "units": "dimensionless, eqs. (4)-(6) of the paper"})


def _group_ends(method: HarmonicBalance, group: ChainParams, z_start: np.ndarray,
                tangent: np.ndarray, v0: float, tuned) -> dict:
    """`_ends` of one group of lanes (stacked chains), each started from the tuned
    orbit z_start: a task that `Followers` may run in another process."""
    from .._engine.engines import Smoothed

    engine = Smoothed(eps=method.eps).for_orbits(*MULTIPLIER_TOLERANCES)
    lanes = np.shape(group.v_d)[0]
    return _ends(_Draws(method, group, engine, PseudoArclength()),
                 np.broadcast_to(z_start, (lanes, np.size(z_start))), tangent, v0, tuned)


def _part(params: ChainParams, sigma: float, draws: int, method: HarmonicBalance,
          tuned: BranchRange, site: int, lanes: int, pool, store):
    """One sigma of `localized_ranges`: its groups submitted to `pool` (none where
    `store` holds the same settings' part). Returns a function of the progress bar
    that waits for them and returns the part, a Dataset over `draw`, written to
    `store` as it is complete."""
    import xarray as xr

    from .._sweeps.result_store import read_dataset, write_dataset
    from .magnification import lane_groups
    from .response import method_settings

    settings = {"chain": chain_record(params), "method": method_settings(method),
                "sigma": sigma, "draws": draws, "site": site,
                "march": [STEP, MAX_STEPS, REFINEMENTS, BISECTIONS, FOLD_WIDTH,
                          *MULTIPLIER_TOLERANCES], "procedure": PROCEDURE}
    path = None
    if store is not None:
        path = Path(store) / f"sigma{sigma:.6g}.nc"
        stored = read_dataset(path, "localized-ranges", **settings)
        if stored is not None:
            def read_back(bar):
                bar.update(draws)
                return stored
            return read_back
    chains = mistuned_lanes(params, sigma, draws)
    branch = tuned.branch
    k = int(np.argmin(np.abs(branch.p - float(params.v_d))))
    z = np.concatenate([branch.u, branch.p[:, None]], axis=1)
    tangent = z[min(k + 1, len(z) - 1)] - z[max(k - 1, 0)]
    tangent = tangent * np.sign(tangent[-1]) / np.linalg.norm(tangent)
    groups = lane_groups(draws + 1, lanes)
    futures = [pool.submit(_group_ends, method,
                           jax.tree_util.tree_map(lambda a: np.asarray(a)[padded], chains),
                           z[k], tangent, float(branch.p[k]), float(params.stiffness))
               for _, padded in groups]

    def finish(bar):
        outs = []
        for (index, _), future in zip(groups, futures):
            outs.append({name: np.asarray(v)[:index.size] for name, v in future.result().items()})
            bar.update(index.size - (index[0] == 0))
        ends = {name: np.concatenate([o[name] for o in outs]) for name in outs[0]}
        part = xr.Dataset({name: ("draw", value[1:]) for name, value in ends.items()},
                          attrs={"tuned_low_lanes": float(ends["low"][0]),
                                 "tuned_high_lanes": float(ends["high"][0])})
        if path is not None:
            path.parent.mkdir(parents=True, exist_ok=True)
            write_dataset(part, path, "localized-ranges", **settings)
        return part

    return finish


def shooting_ranges(params: ChainParams, sigma: float, draws, *, eps: float, site: int = 0,
                    workers: int = 1) -> list[dict]:
    """The stable ranges of the given draws at strength sigma by shooting on the
    smoothed model at `eps` (Tsit5 at 1e-10/1e-12, `for_orbits`) and the driver
    (`branch_range` with `Shooting`): the independent check of `localized_ranges`,
    one branch per draw (a minute or more each on the ring of 20), `workers`
    processes side by side (`Followers`).

    **Arguments:** `params`, `sigma`, `site`, `workers` as `localized_ranges`'s;
    `draws`: the draws' indices (0-based: draw d is `mistuned_lanes`'s lane d + 1);
    `eps`: the smoothing velocity (> 0, dimensionless).

    **Returns:** one dict per draw: `draw`, `low`, `low_kind`, `high`, `high_kind`
    (dimensionless v_d; None, with `error`, where the branch gives no range).

    **Raises:** `ValidationError` for a bad eps, sigma or workers.
    """
    from .._engine.engines import Smoothed
    from .pool import Followers

    check_count("workers", workers)
    Smoothed(eps=eps)  # a bad eps is refused here, before any process starts
    draws = [int(d) for d in draws]
    chains = mistuned_lanes(params, sigma, max(draws) + 1)
    with Followers(workers, one_thread=True) as pool:
        futures = [pool.submit(_shooting_range, jax.tree_util.tree_map(
            lambda a: np.asarray(a)[d + 1], chains), eps, site) for d in draws]
        return [{"draw": d} | future.result() for d, future in zip(draws, futures)]


def _shooting_range(chain: ChainParams, eps: float, site: int) -> dict:
    """One draw of `shooting_ranges`: a task that `Followers` may run in another
    process."""
    from .._bifurcation.shooting import Shooting
    from .._engine.engines import Smoothed

    try:
        r = branch_range(chain, Shooting(Smoothed(eps=eps).for_orbits()), site=site)
    except RuntimeError as error:
        return {"low": None, "low_kind": None, "high": None, "high_kind": None,
                "error": str(error)}
    return {"low": r.low, "low_kind": r.low_kind, "high": r.high, "high_kind": r.high_kind}
