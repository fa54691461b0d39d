"""The snake's branches checked: their stable ranges, the accuracy of their
Floquet multipliers, and direct simulation at the ends of each stable range."""

from __future__ import annotations

from typing import TYPE_CHECKING

import jax.numpy as jnp
import numpy as np

from ..._bifurcation.shooting import unpack
from ..._engine.options import SimulationOptions
from ..._engine.progress import tqdm
from ..._engine.simulate import simulate
from ..._physics.initial import GivenState
from ..._physics.params import ChainParams, with_parameter
from ..._bifurcation.branch_file import bifurcation_records, stored_branch
from .starts import _downward_crossings

if TYPE_CHECKING:  # heavy: imported where they are used
    import xarray as xr


def stable_ranges(branch: xr.Dataset) -> list[dict]:
    """The stable segments of a joined branch: their v_d ranges, each end the
    bifurcation located there (or the end of the computed branch), and for each
    end the index of its last stable point and of the first point beyond it
    (None at the end of the branch)."""
    stable = branch["stable"].values
    v = branch["v_d"].values
    bifs = bifurcation_records(stored_branch(branch))
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
            out.append(_simulated_side(orbits, params, branch, options, rng, perturbation,
                                       end, side, vd, start, expected))
    return out


def _simulated_side(orbits, params: ChainParams, branch: xr.Dataset, options, rng,
                    perturbation: float, end: dict, side: str, vd: float, start: int,
                    expected) -> dict:
    """One row of `_check_by_simulation`: the simulation at v_d = `vd` from the
    branch's orbit `start`, its positions perturbed, and whether the state
    persists there (the orbit's sites on the HALC with the same phase lags)."""
    v = branch["v_d"].values
    y_orbit, _ = unpack(jnp.asarray(branch["u"].values[start]))
    a = branch["amplitudes"].values[start]
    sites = np.flatnonzero(a > 0.5 * a.max())
    lags = _phase_lags(orbits, with_parameter(params, "v_d", float(v[start])), y_orbit, sites)
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
    return {"end": end["type"], "end_v_d": end["v_d"], "side": side,
            "v_d": float(vd), "start_v_d": float(v[start]),
            "sites_orbit": sites.tolist(), "sites_simulation": sim_sites.tolist(),
            "phase_lag_difference": lag_difference, "persists": persists,
            "expected_growth": expected,
            "agrees": (persists == (side == "inside")) if resolved else None}


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
