"""The snake on a small ring: shooting from simulated chain states, Floquet
multipliers against their closed-form estimate, stable ends against direct simulation,
the stored branches read back, and the command line.

Its subject is also the snake's and its branch driver's internals: the starts, the
store and the summary, and (at the end of the file) the branch driver's switching and
deflation steps (`critical_directions`, `symmetric_directions`, `switch_by_deflation`,
the switching with its fallbacks, the steps along a symmetry's axes, the deflation
operator and the ring's symmetries) and the snake's orchestration of them (a failed
branch or switch, deflated orbits from a start without one, or on a branch already
followed, resuming), provoked or spied on through its private functions."""

import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import xarray as xr
from scipy.integrate import solve_ivp

import jaxchain as jc
from jaxchain._bifurcation.deflation import chain_symmetries, deflation
# building blocks of `switch_branch` and of the snake's switching, tested on their own
from jaxchain._bifurcation.branch_switching import (critical_directions,
                                                     switch_by_deflation,
                                                     symmetric_directions)

from helpers import (RING_OF_THREE, RING_OF_TWO, SETTLED, SHOOTING_OF_THREE,
                     SHOOTING_OF_TWO, assert_usage_error, copies_distance, internal,
                     internal_module, packed, reference_rhs, replace_internal,
                     scipy_return, start_residual, switched_on_ring_of_two)

RING = jc.ChainParams(n_osc=4, v_d=1.5)
#: Shooting on the exact stick/slip model: Newton's method through every switch (the
#: snake's on the exact engine, `Shooting.from_simulations(jc.Exact())`).
EXACT = jc.Shooting(jc.Exact().for_orbits())
OPTIONS = jc.ContinuationOptions(ds=0.02, ds_max=0.1, p_min=1.2, p_max=1.75, max_points=14)


@pytest.fixture(scope="module")
def one_site(tmp_path_factory):
    out = tmp_path_factory.mktemp("snake")
    found = jc.localized_branches(RING, (1,), continuation_options=OPTIONS, out=out)
    return found, out


@pytest.mark.study
@pytest.mark.numerics
@pytest.mark.long
def test_shooting_from_simulation_gives_the_simulated_state_and_its_multipliers():
    """The 1-site state of a ring of 4 at v_d = 1.5: the orbit has the simulated
    energy (within 0.5 %) and sites; the trivial multiplier is 1 to 1e-6; each quiet
    oscillator contributes a pair of modulus about exp(-(2 xi - |mu'(v_d)|) T / 2)."""
    orbit, sim, reason = internal("snake start orbits")(RING, (1,))[1]
    assert reason is None and bool(orbit.converged)
    assert int(orbit.n_halc) == sim["n_halc"] == 1
    assert abs(float(orbit.energy) / sim["energy"] - 1) < 5e-3
    m = np.asarray(orbit.multipliers)
    assert abs(m[int(orbit.trivial)] - 1) < 1e-6
    f = RING.friction
    slope = (f.mu_st - f.mu_d) / f.v0 * np.exp(-RING.v_d / f.v0)  # |mu'(v_d)|, eq. (1)
    quiet = np.exp(-(2 * RING.xi - slope) * float(orbit.period) / 2)
    others = np.delete(np.abs(m), int(orbit.trivial))
    assert abs(others[0] / quiet - 1) < 0.02  # the largest: a quiet oscillator's pair


@pytest.mark.numerics
@pytest.mark.study
def test_the_one_site_branch_ends_where_simulation_says(one_site):
    """Its low end is a Neimark-Sacker point (a complex pair leaves the unit circle:
    the quiet neighbours start to oscillate), and direct simulation keeps the state
    just above it and loses it just below."""
    found, _ = one_site
    (branch,) = found["summary"]["branches"]
    assert branch["sites"] == 1 and len(branch["stable_ranges"]) == 1
    low = branch["stable_range_ends"][0][0]
    assert low["type"] == "Neimark-Sacker" and 1.2 < low["v_d"] < 1.5
    assert abs(low["multiplier"][1]) > 1e-3  # complex
    checks = [c for c in branch["simulation_check"] if c["end"] == "Neimark-Sacker"]
    assert {c["side"]: c["agrees"] for c in checks} == {"inside": True, "outside": True}
    assert branch["largest_trivial_multiplier_error"] < 1e-6


@pytest.mark.numerics
@pytest.mark.study
def test_continuation_reproduces_itself_from_a_perturbed_start(one_site):
    """The Neimark-Sacker point again, from the starting orbit perturbed by a
    relative 1e-6: the same belt speed to 1e-6."""
    found, _ = one_site
    ds = found["datasets"]["k=1"]
    low = found["summary"]["branches"][0]["stable_range_ends"][0][0]["v_d"]
    start = int(np.argmin(np.abs(ds["v_d"].values - 1.5)))
    u = ds["u"].values[start] * (1 + 1e-6)
    params = jc.with_parameter(RING, "v_d", float(ds["v_d"].values[start]))
    method = jc.Shooting(root_finder="levenberg-marquardt",
                         phase_oscillator=int(ds.attrs["phase_oscillator"]))
    orbit = jc.periodic_orbit(params, (u[:-1].reshape(2, -1), float(u[-1])), method)
    problem = jc.cycle_problem(orbit, method)
    branch = jc.continuation(problem, options=jc.ContinuationOptions(
        ds=0.02, ds_max=0.1, p_min=1.2, p_max=1.75, max_points=14, direction=-1))
    ns = [b for b in jc.locate_bifurcations(problem, branch) if b.kind == "Neimark-Sacker"]
    assert len(ns) == 1 and abs(float(ns[0].p) - low) < 1e-6


@pytest.mark.study
@pytest.mark.long
def test_exact_one_site_branch_ends_where_the_exact_simulation_says(one_site, tmp_path,
                                                                     capsys):
    """The same branch on the exact stick/slip model (`jaxchain snake --engine
    exact`: exact shooting, exact multipliers, exact simulations), started at v_d
    1.34: its low end is a Neimark-Sacker point too, and direct simulation on the
    exact engine (event by event, not shooting) keeps the state just inside and
    loses it just outside. The smoothed model's point (eps 1e-3, the fixture) lies
    within 0.01 of it, the smoothing error of the landed boundaries (issue 56); the
    exact multipliers change by less than 1e-8 at 100 times looser tolerances."""
    argv = ["snake", "--engine", "exact", "--n-osc", "4", "--vd", "1.34", "--sites", "1",
            "--vd-min", "1.28", "--vd-max", "1.37", "--max-points", "12",
            "--out", str(tmp_path), "--json"]
    assert jc.main(argv) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["engine"] == "exact" and "eps" not in doc
    (branch,) = doc["branches"]
    low = branch["stable_range_ends"][0][0]
    assert low["type"] == "Neimark-Sacker" and abs(low["multiplier"][1]) > 1e-3
    checks = [c for c in branch["simulation_check"] if c["end"] == "Neimark-Sacker"]
    assert {c["side"]: c["agrees"] for c in checks} == {"inside": True, "outside": True}
    assert branch["multiplier_accuracy"]["critical_difference"] < 1e-8
    smoothed = one_site[0]["summary"]["branches"][0]["stable_range_ends"][0][0]
    assert smoothed["type"] == "Neimark-Sacker" and abs(smoothed["v_d"] - low["v_d"]) < 0.01


@pytest.fixture(scope="module")
def exact_one_site_end(tmp_path_factory):
    """The exact one-site and whole-ring branches of the ring of 4 continued from v_d
    1.72 up to their ends (`jaxchain snake --engine exact`, with its checks by
    simulation): the summary of each (by k) and the stored one-site branch."""
    out = tmp_path_factory.mktemp("exact_end")
    argv = ["snake", "--engine", "exact", "--n-osc", "4", "--vd", "1.72", "--sites", "1,4",
            "--vd-min", "1.7", "--vd-max", "1.85", "--max-points", "40", "--no-switch",
            "--out", str(out), "--json"]
    assert jc.main(argv) == 0
    branches = json.loads((out / "snake.json").read_text())["branches"]
    return ({b["excited"]: b for b in branches},
            xr.load_dataset(out / "snake" / "branch_k1.nc"))


@pytest.mark.study
@pytest.mark.long
def test_exact_one_site_branch_ends_where_its_stick_phase_vanishes(exact_one_site_end):
    """Upwards in v_d the exact one-site branch of the ring of 4 ends at a sliding
    bifurcation: the excited oscillator's stick phase shrinks like a square root,
    d^2 ~ c (p* - v_d), and no orbit lies beyond. `locate_sliding` puts p* by the
    secant method on d^2 = 0. Checked by direct simulation on the exact engine
    (event by event over 80 periods from the branch's last orbit, not shooting):
    just below p* the state keeps its stick phase, and the line through d^2 at
    p* - 4e-5 and p* - 1e-5 meets zero at p* within 1e-6 (bisection on the flag
    of the stick phase was 1e-5 off); just above it the stick is gone. The command's
    check by simulation treats the end as the end of the state (it crashed on a
    bifurcation with no orbit beyond it)."""
    branches, ds = exact_one_site_end
    high = branches[1]["stable_range_ends"][0][1]
    assert high["type"] == "sliding" and high["width"] < 1e-8 and high["n_halc"] == 1
    # no orbit beyond the end: the command's own check simulates 0.03 past it, where
    # the state is lost, and 0.03 inside, where it persists
    checks = {c["side"]: c for c in branches[1]["simulation_check"] if c["end"] == "sliding"}
    assert checks["outside"]["v_d"] > high["v_d"] > checks["inside"]["v_d"]
    assert checks["inside"]["agrees"] and checks["outside"]["agrees"]
    p_star = high["v_d"]
    u = ds["u"].values[int(np.argmax(ds["v_d"].values))]
    excited = int(ds.attrs["phase_oscillator"])  # the oscillator of largest amplitude

    def stick(v_d):
        obs = jc.simulate(jc.with_parameter(RING, "v_d", v_d), u[:-1].reshape(2, -1),
                          engine=jc.Exact(jc.NonsmoothOptions.reference(t_end=600.0,
                                                                  transient=500.0)))
        t, osc, kind = (np.asarray(a) for a in (obs.log_time, obs.log_osc, obs.log_kind))
        t, kind = t[osc == excited], kind[osc == excited]
        phases = [t[i + 1] - t[i] for i in range(t.size - 1)
                  if jc.SWITCH_KINDS[kind[i]] == "slip to stick"
                  and jc.SWITCH_KINDS[kind[i + 1]] == "stick to slip"]
        return phases[-1] if phases else None

    (p1, d1), (p2, d2) = ((p_star - delta, stick(p_star - delta)) for delta in (4e-5, 1e-5))
    assert d1 is not None and d2 is not None and d2 < d1
    assert abs(p2 - d2**2 * (p2 - p1) / (d2**2 - d1**2) - p_star) < 1e-6
    assert stick(p_star + 1e-5) is None


@pytest.mark.study
@pytest.mark.long
def test_past_the_whole_ring_s_branch_point_the_check_sees_steady_sliding(
        exact_one_site_end):
    """The whole ring (all four on the HALC) loses stability at a branch point. Just
    past it the command's check simulates from the unstable orbit, and the chain
    decays to steady sliding, which is stable there: v_d lies above the ring's Hopf
    point (`hopf_point`, the linearization of steady sliding, independent of any
    simulation). Its vanishing oscillation keeps the orbit's pattern, which the
    check had counted as the state persisting; the sites must stick (`on_halc`)."""
    branches, _ = exact_one_site_end
    ring = branches[4]
    (end,) = [e for r in ring["stable_range_ends"] for e in r if e["type"] == "branch point"]
    outside = next(c for c in ring["simulation_check"]
                   if c["end"] == "branch point" and c["side"] == "outside")
    assert outside["v_d"] > end["v_d"] > float(jc.hopf_point(RING, 1.0).v_d[0])
    assert outside["sites_simulation"] == [] and not outside["persists"]
    assert all(c["agrees"] for c in ring["simulation_check"])


@pytest.mark.study
@pytest.mark.long
def test_the_one_site_edge_tends_to_the_single_oscillator_s_limit_as_eta_c_vanishes(
        exact_one_site_end):
    """The one-site branch's sliding point (the edge of the excited oscillator's
    stick-slip cycle) followed in the coupling (`sliding_curve`) tends to the
    uncoupled oscillator's existence limit L (`stick_slip_existence_limit`, closed
    form) as eta_c -> 0, quadratically: the neighbours respond at O(eta_c) and act
    back at O(eta_c^2), so (L - p*) / eta_c^2 is the same at eta_c 0.0025 and 0.005
    to within a few per cent (on the ring of 20 it runs 358.9, 355.5, 352.6 at
    0.005, 0.01, 0.015), while L - p* itself changes fourfold."""
    branches, ds = exact_one_site_end
    ok = ds["critical_multiplier_abs"].values < 1  # stick-slip orbits, before the end
    i = int(np.argmax(np.where(ok, ds["v_d"].values, -np.inf)))
    u, v_d = ds["u"].values[i], float(ds["v_d"].values[i])
    method = EXACT.with_phase_oscillator(int(ds.attrs["phase_oscillator"]))
    orbit = jc.periodic_orbit(jc.with_parameter(RING, "v_d", v_d),
                              (u[:-1].reshape(2, -1), u[-1]), method)
    problem = jc.cycle_problem(orbit, method)
    point = jc.locate_sliding(problem, np.append(u, v_d))
    assert point.converged and abs(
        float(point.p) - branches[1]["stable_range_ends"][0][1]["v_d"]) < 1e-8
    values = [0.0025, 0.005, float(RING.eta_c)]
    curve = jc.sliding_curve(problem, point, "eta_c", values)
    assert np.asarray(curve.converged).all()
    limit = jc.stick_slip_existence_limit(jc.ChainParams(n_osc=1))
    gap = limit - np.asarray(curve.p)
    assert (gap > 0).all() and gap[1] / gap[0] > 3.5
    c = gap / np.asarray(values) ** 2
    assert abs(c[0] - c[1]) < 0.03 * c[1], c


@pytest.mark.study
def test_stored_branches_are_read_back_only_for_equal_settings(one_site):
    found, out = one_site
    again = jc.localized_branches(RING, (1,), continuation_options=OPTIONS, out=out,
                               simulation_check=False)
    a, b = found["datasets"]["k=1"], again["datasets"]["k=1"]
    np.testing.assert_array_equal(a["energy"].values, b["energy"].values)
    assert again["summary"]["branches"][0]["bifurcations"] == \
        found["summary"]["branches"][0]["bifurcations"]
    other = jc.ContinuationOptions(ds=0.02, ds_max=0.1, p_min=1.3, p_max=1.75, max_points=4)
    fresh = jc.localized_branches(RING, (1,), continuation_options=other, out=out,
                               simulation_check=False)
    assert fresh["datasets"]["k=1"].sizes["point"] <= 7 < a.sizes["point"]  # recomputed


@pytest.mark.study
@pytest.mark.numerics
@pytest.mark.long
def test_recurrences_of_a_periodic_orbit_return_after_one_period():
    """On the single oscillator's exact stick-slip cycle every turning point x' = 0
    (from + to -) comes back after one period: the guesses of `_recurrences` are
    each a period apart to the sampling step (1e-3), the first one first, and each
    state returns to itself to the flow's accuracy after its time to the next."""
    one = jc.ChainParams(n_osc=1, v_d=1.5)
    orbits = internal("snake orbits")(EXACT)
    cycle = jc.periodic_orbit(one, (np.array([[2.2], [0.0]]), 6.3), EXACT)
    start = orbits.samples(one, cycle.y0, np.array([0.0, 1.0]))[-1]
    guesses = internal_module("snake symmetric orbit")._recurrences(orbits, one, start, 0)
    # the first turning point after `start` is the orbit's y0, T - 1 later
    assert len(guesses) == 5
    np.testing.assert_allclose(guesses[0][0], cycle.y0, atol=5e-3)
    for y, period in guesses:
        assert period == pytest.approx(float(cycle.period), abs=1e-3)
        back = orbits.samples(one, y, np.array([0.0, float(cycle.period)]))[-1]
        np.testing.assert_allclose(back, y, atol=1e-8)


def test_eq8_on_the_ring_is_fixed_by_the_reflection_about_an_odd_block_s_centre():
    """The isotropy subgroup of eq. (8)'s state on the ring of eight (signs (-1)^n):
    for an odd block, the identity and the reflection about the block's centre (an
    involution mapping the block onto itself); for an even block, the identity
    alone (the reflection swaps the signs); for the whole ring, the rotations by
    an even number of sites and the reflections through a site, eight in all; on
    a chain that is not a homogeneous ring, the identity."""
    starts = internal_module("snake symmetric orbit")
    ring = jc.ChainParams(n_osc=8, v_d=1.5)
    ident = np.arange(8)
    for k in range(1, 9):
        mask = starts.start_mask(ring.graph, k)
        perms = starts.isotropy(ring, jc.OutOfPhaseExcitation.eq8(mask)(ring).reshape(2, 8))
        assert np.array_equal(perms[0], ident)
        if k == 8:
            assert len(perms) == 8
        elif k % 2:
            assert len(perms) == 2
            r = perms[1]
            assert np.array_equal(r[r], ident) and np.array_equal(mask[r], mask)
            assert np.sum(r == ident) == 2  # a reflection through two sites of an even ring
        else:
            assert len(perms) == 1
    mistuned = jc.ChainParams(n_osc=8, v_d=1.5, xi=np.linspace(0.05, 0.06, 8))
    y = jc.OutOfPhaseExcitation.eq8(starts.start_mask(mistuned.graph, 3))(mistuned)
    assert len(starts.isotropy(mistuned, y.reshape(2, 8))) == 1


@pytest.mark.numerics
@pytest.mark.study
@pytest.mark.long
def test_inside_its_fixed_subspace_the_symmetric_start_reaches_an_orbit_unstable_across_it():
    """Eq. (8) with five of the ring of eight's oscillators excited, simulated
    inside the fixed subspace of its reflection (`symmetric_state`) and shot from
    there, gives a five-site orbit fixed by the reflection that is unstable (a
    Floquet multiplier beyond 1) only across that subspace: the monodromy matrix
    restricted to it, by central finite differences of the exact engine's flow
    (`Exact.flow`) along an orthonormal basis of the subspace, has no
    multiplier beyond 1 + 1e-3, and the one at 1 (the flow's direction) is
    among them."""
    starts = internal_module("snake symmetric orbit")
    orbits = internal("snake orbits")(EXACT)
    at = jc.ChainParams(n_osc=8, v_d=1.5)
    start = np.asarray(jc.OutOfPhaseExcitation.eq8(starts.start_mask(at.graph, 5))(at))
    perms = starts.isotropy(at, start.reshape(2, 8))
    orbit, why, _ = internal("snake symmetric orbit")(orbits, at, start.reshape(2, 8), perms,
                                                      3000.0)
    assert why is None and int(orbit.n_halc) == 5
    y0, period, r = np.asarray(orbit.y0), float(orbit.period), perms[1]
    np.testing.assert_allclose(y0[:, r], y0, atol=1e-8)
    assert np.max(np.abs(np.asarray(orbit.multipliers))) > 1.0 + 1e-3
    # an orthonormal basis of the fixed subspace: e_n + e_r(n), normalised
    pairs = sorted({tuple(sorted((n, int(r[n])))) for n in range(8)})
    basis = []
    for row in range(2):
        for pair in pairs:
            e = np.zeros((2, 8))
            e[row, list(pair)] = 1.0
            basis.append(e / np.linalg.norm(e))
    h, flow = 1e-6, EXACT.engine.flow
    columns = []
    for e in basis:
        ends = [np.asarray(flow(at, jnp.asarray(y0 + s * h * e), jnp.array([period]))[-1])
                for s in (1, -1)]
        columns.append((ends[0] - ends[1]).reshape(-1) / (2 * h))
    restricted = np.stack([e.reshape(-1) for e in basis]) @ np.stack(columns, axis=1)
    moduli = np.abs(np.linalg.eigvals(restricted))
    assert np.max(moduli) < 1.0 + 1e-3
    assert np.min(np.abs(moduli - 1.0)) < 1e-3


def test_a_start_that_loses_its_pattern_is_tried_at_the_neighbouring_speeds(monkeypatch):
    """A start whose orbit at v_d has another number of sites on the HALC than it
    excites is simulated again at v_d -+ 0.1, like one with no periodic orbit: the
    first orbit that keeps its number of sites is kept, else the orbit it had (or,
    with none, the first orbit found, or with none anywhere, the reasons of every
    speed); a start that keeps its pattern is not tried again. `_shoot_starts` is
    replaced by a table of outcomes (n_HALC, None for no periodic orbit) for each
    belt speed."""
    table = {1.5: {1: None, 2: 3, 3: 4, 4: None, 5: 5, 6: None},
             1.4: {1: 2, 2: 3, 3: 4, 4: 5, 6: None},
             1.6: {1: 1, 2: 3, 3: 3, 4: None, 6: None}}
    tried = []

    class Orbit:
        def __init__(self, n_halc, v_d):
            self.n_halc, self.v_d = n_halc, v_d

    def outcomes(orbits, params, sites, vds, options, progress):
        tried.append((tuple(sites), tuple(round(v, 9) for v in vds)))
        return {v: {k: (None, {}, "not periodic") if table[round(v, 9)][k] is None
                    else (Orbit(table[round(v, 9)][k], round(v, 9)), {}, None)
                    for k in sites} for v in vds}

    replace_internal(monkeypatch, "snake starts at speeds", outcomes)
    ring = jc.ChainParams(n_osc=8, v_d=1.5)
    out = internal("snake starts")(None, ring, (1, 2, 3, 4, 5, 6), jc.SimulationOptions(),
                                   False)
    assert tried == [((1, 2, 3, 4, 5, 6), (1.5,)), ((1, 2, 3, 4, 6), (1.4, 1.6))]
    failed = out.pop(6)
    assert failed[0] is None and failed[2] == ("not periodic; at v_d 1.4: not periodic, "
                                               "1.6: not periodic")
    chosen = {k: (o.v_d, o.n_halc) for k, (o, _, _) in out.items()}
    assert chosen == {1: (1.6, 1), 2: (1.5, 3), 3: (1.6, 3), 4: (1.4, 5), 5: (1.5, 5)}
    assert [out[k][1]["v_d"] for k in (1, 2, 3, 4, 5)] == [1.6, 1.5, 1.6, 1.4, 1.5]


def test_a_start_without_its_own_orbit_is_simulated_inside_its_fixed_subspace(monkeypatch):
    """After the neighbouring speeds, a start with no orbit of its own number of
    sites whose eq. (8) state a reflection fixes (an odd k on the ring) is tried
    inside that fixed subspace at v_d, then at v_d -+ 0.1: the first orbit with its
    own number of sites is kept, marked `symmetric`, at its own v_d with its own
    phase oscillator; an even start (no symmetry) and a start with its own orbit
    are not tried; a start that fails there too keeps the orbit it had, or with
    none its reasons, extended. `_shoot_starts` and `_symmetric_orbit` are
    replaced by tables of outcomes (n_HALC, None for no periodic orbit)."""
    plain = {1.5: {1: None, 3: 4, 4: None, 5: None, 7: 7},
             1.4: {1: None, 3: 4, 4: None, 5: None},
             1.6: {1: None, 3: 4, 4: None, 5: None}}
    inside = {1.5: {1: 1, 3: 2, 5: None}, 1.4: {3: 3, 5: None}, 1.6: {5: 6}}
    tried = []

    class Orbit:
        def __init__(self, n_halc, v_d):
            self.n_halc, self.v_d, self.energy = n_halc, v_d, 1.0

    def outcomes(orbits, params, sites, vds, options, progress):
        return {v: {k: (None, {}, "not periodic") if plain[round(v, 9)][k] is None
                    else (Orbit(plain[round(v, 9)][k], round(v, 9)), {}, None)
                    for k in sites} for v in vds}

    def symmetric(orbits, at, start, perms, t_end):
        v, k = round(float(at.v_d), 9), int(np.sum(np.abs(start[0] - start[0, 0]) > 1e-12))
        tried.append((k, v, len(perms)))
        n = inside[v][k]
        return (None, "not periodic", 0) if n is None else (Orbit(n, v), None, 9)

    replace_internal(monkeypatch, "snake starts at speeds", outcomes)
    replace_internal(monkeypatch, "snake symmetric orbit", symmetric)
    ring = jc.ChainParams(n_osc=8, v_d=1.5)
    out = internal("snake starts")(None, ring, (1, 3, 4, 5, 7), jc.SimulationOptions(), False)
    assert tried == [(1, 1.5, 2), (3, 1.5, 2), (3, 1.4, 2), (5, 1.5, 2), (5, 1.4, 2),
                     (5, 1.6, 2)]
    assert {k: (o.v_d, o.n_halc) for k, (o, _, _) in out.items() if o is not None} == {
        1: (1.5, 1), 3: (1.4, 3), 7: (1.5, 7)}
    assert out[1][1] == {"n_halc": 1, "energy": 1.0, "phase_oscillator": 9, "v_d": 1.5,
                         "symmetric": True}
    assert out[3][1]["v_d"] == 1.4 and out[3][2] is None and "symmetric" not in out[7][1]
    assert out[4][0] is None and "fixed subspace" not in out[4][2]
    assert out[5][0] is None and out[5][2].endswith(
        "; inside the fixed subspace of its symmetry, at v_d 1.5: not periodic, 1.4: not "
        "periodic, 1.6: 6 sites on the HALC")


def test_neighbouring_numbers_of_sites_connect_where_one_joined_set_of_branches_has_both(
        capsys):
    """`_sites_connections` on four branches drawn by hand: A (one site, then none
    past a sliding point), B (two sites) meeting C (two, then three sites), and D
    (four sites) alone. 0 and 1 connect along A; 1 and 2 do not (A meets neither
    B nor C); 2 and 3 connect through B and C, stable ones too (B stable with two
    sites, C with three); 3 and 4 do not; nothing carries 5. The command prints
    one line per pair."""
    def branch(n_halc, stable):
        return xr.Dataset({"n_halc": ("point", np.array(n_halc)),
                           "stable": ("point", np.array(stable, dtype=bool))})

    datasets = {"A": branch([1, 1, 1, 0, 0], [1, 1, 0, 0, 0]),
                "B": branch([2, 2, 2], [1, 1, 0]), "C": branch([2, 3, 3], [0, 0, 1]),
                "D": branch([4, 4], [1, 1])}
    links = {"A": [], "B": ["C"], "C": ["B", "steady sliding"], "D": []}
    out = internal("snake sites connections")(datasets, links, 5)
    assert [c["sites"] for c in out] == [[n, n + 1] for n in range(5)]
    assert [c["connected"] for c in out] == [True, False, True, False, False]
    assert [c["stable_connected"] for c in out] == [False, False, True, False, False]
    assert out[0]["through"] == [["A"]] and out[2]["through"] == [["B", "C"]]
    assert out[1]["with_n"] == ["A"] and out[1]["with_n_plus_1"] == ["B", "C"]
    assert out[4]["with_n"] == ["D"] and out[4]["with_n_plus_1"] == []
    internal("snake summary lines")({"branches": [], "not_periodic": [],
                                     "sites_connections": out})
    lines = capsys.readouterr().out.splitlines()
    assert lines == [
        "0 and 1 sites: connected through A, not the stable ones",
        "1 and 2 sites: not connected (no branch, nor branches that meet, carry both)",
        "2 and 3 sites: connected through B (and 1 more joined to it), stable ones too",
        "3 and 4 sites: not connected (no branch, nor branches that meet, carry both)",
        "4 and 5 sites: no orbit with 5 sites found"]


@pytest.mark.numerics
@pytest.mark.study
def test_snake_command_json_and_bad_options(tmp_path, capsys):
    """The command's branch, read back from its file, against scipy: each stored
    point (the state and period of `u`) is a periodic orbit of eq. (5) at its belt
    speed, with its n_HALC and amplitudes."""
    # The ring of `RING` (n_osc 4): the programs that `one_site` compiled serve the
    # command too, which still shoots, continues and stores its own branch.
    code = jc.main(["snake", "--n-osc", "4", "--sites", "1", "--max-points", "4",
                    "--no-simulation", "--out", str(tmp_path), "--json", "--no-progress"])
    assert code == 0
    out = json.loads(capsys.readouterr().out)
    assert set(out["outputs"]) == {"snake", "snake.png", "snake.json"}
    (branch,) = out["branches"]
    assert set(branch) >= {"sites", "stable_ranges", "bifurcations", "connects_to"}
    assert branch["sites"] == 1 and (tmp_path / "snake.png").exists()
    ds = xr.load_dataset(tmp_path / "snake" / "branch_k1.nc", engine="h5netcdf")
    assert ds.sizes["point"] >= 2
    for i in range(ds.sizes["point"]):
        u = ds["u"].values[i]
        y0, period = u[:-1], u[-1]
        params = jc.with_parameter(RING, "v_d", float(ds["v_d"].values[i]))
        ts = np.linspace(0.0, period, 6001)
        ref = solve_ivp(reference_rhs(params), (0.0, period), y0, method="LSODA",
                        rtol=1e-10, atol=1e-12, t_eval=ts)
        assert np.max(np.abs(ref.y[:, -1] - y0)) < 1e-6, i  # periodic
        x = ref.y[:4]
        assert np.allclose(ds["amplitudes"].values[i], 0.5 * (x.max(1) - x.min(1)), rtol=1e-3)
        sticks = (np.min(np.abs(ref.y[4:] - params.v_d), axis=1)
                  < 3.0 * float(jc.Smoothed().eps))
        assert int(ds["n_halc"].values[i]) == int(sticks.sum()) == 1, i
    assert_usage_error(["snake", "--sites", "0"], "--sites", capsys)
    assert_usage_error(["snake", "--vd", "3"], "--vd", capsys)
    # "all" is every k = 1 ... N, accepted as starts: the error is the belt speed's
    assert_usage_error(["snake", "--sites", "all", "--vd", "3"], "--vd must lie", capsys)


#: The settings that the previous release keyed the default smoothed and exact
#: snakes' stored branches by (its ShootingOptions and ExactShooting, as
#: `canonical` wrote them): a store of the ring of 8 or 20 made then reads back.
PREVIOUS_SETTINGS = [
    '{"engine": "smoothed", "eps": 0.001, "shooting": {"class": "jaxchain._bifurcation.'
    'shooting.ShootingOptions", "fields": {"atol": 1e-12, "max_steps": 200000, "n_samples":'
    ' 4096, "newton_steps": 40, "newton_tol": 1e-09, "phase_oscillator": 0, "root_finder": '
    '"levenberg-marquardt", "rtol": 1e-10, "solver": {"class": "diffrax._solver.tsit5.Tsit5"'
    ', "fields": {"scan_kind": null}}}}, "solver": "ros34pw2"}',
    '{"engine": "exact", "shooting": {"class": "jaxchain._bifurcation.exact_orbit.ExactShoot'
    'ing", "fields": {"damped_steps": 120, "flow": {"class": "jaxchain._engine.exact.options'
    '.NonsmoothOptions", "fields": {"adjoint": "forward", "atol": 1e-12, "chunk_length": 250'
    '.0, "held": [], "log_size": 1024, "max_events": 100000, "max_steps": 100000, "root_tol"'
    ': 1e-13, "rtol": 1e-12, "solver": "tsit5", "switch_tol": 1e-09, "t_end": 1.0, "transie'
    'nt": 0.0}}, "n_samples": 4096, "newton_steps": 40, "newton_tol": 1e-09, "phase_oscillat'
    'or": 0}}}',
]


def test_the_default_snakes_keep_the_previous_releases_store_key():
    from jaxchain._engine.hashes import canonical  # the store's key, as it is written

    orbits = internal("snake orbits")
    now = [orbits(jc.Shooting.from_simulations(jc.Smoothed()), jc.Smoothed()),
           orbits(jc.Shooting.from_simulations(jc.Exact()))]
    for settings, previous in zip(now, PREVIOUS_SETTINGS):
        assert json.dumps(canonical(settings.settings()), sort_keys=True) == previous
    # a method the previous release did not have keys by itself, never by a
    # previous method's key
    damped = jc.Shooting(jc.Smoothed().for_orbits(), damped_steps=120)
    assert "method" in orbits(damped, jc.Smoothed()).settings()


# --- The branch driver's switching and deflation steps and the snake's orchestration:
# private subjects, tested on their own. Branch switching on the ring of two at its
# symmetric two-site state's branch point (`branch_point`, tests/conftest.py) and on
# analytic branch points; deflation on the ring of three at v_d 1.5
# (`ring_of_three_states`, tests/conftest.py). Their public behaviour:
# test_branch_switching.py and test_deflation.py.


@pytest.mark.study
@pytest.mark.long
def test_the_snake_switches_branches_at_its_branch_points(branch_point, tmp_path,
                                                          monkeypatch):
    """`localized_branches` (switch=True, the default) follows the other branch at
    the two-site state's branch point: a branch labelled as switched, starting at the
    branch point that `locate_bifurcations` finds here, with unequal amplitudes,
    connected to its parent both ways; stored and read back whole. The start is
    eq. (8) with both sites excited (with one, the two-site state it reaches has
    not its pattern, and the snake looks for one site at other belt speeds)."""
    _, _, point = branch_point
    kwargs = dict(continuation_options=jc.ContinuationOptions(
        ds=0.02, ds_max=0.1, p_min=1.0, p_max=1.85, max_points=12),
        start_options=jc.SimulationOptions(t_end=2000.0, transient=1500.0),
        simulation_check=False, out=tmp_path)
    found = jc.localized_branches(RING_OF_TWO, (2,), **kwargs)
    labels = [b["label"] for b in found["summary"]["branches"]]
    assert labels == ["k=2", "k=2 switched 1"]
    parent, switched = found["summary"]["branches"]
    assert abs(switched["switched_from_vd"] - float(point.p)) < 1e-6
    assert switched["connects_to"] == ["k=2"] and "k=2 switched 1" in parent["connects_to"]
    amplitudes = found["datasets"]["k=2 switched 1"]["amplitudes"].values
    assert np.all(np.abs(amplitudes[:, 0] - amplitudes[:, 1]) > 1e-5)
    def refuse(*args, **kwargs):
        raise AssertionError("a stored branch was computed again")

    replace_internal(monkeypatch, "snake starts", refuse)
    again = jc.localized_branches(RING_OF_TWO, (2,), **kwargs)  # read back, not recomputed
    assert list(again["datasets"]) == labels
    assert np.array_equal(again["datasets"]["k=2 switched 1"]["u"].values,
                          found["datasets"]["k=2 switched 1"]["u"].values)


@pytest.mark.study
@pytest.mark.long
def test_a_branch_that_fails_is_flagged_and_the_others_are_kept(monkeypatch, tmp_path):
    """The first start's continuation raises (as it did where the start's phase
    condition was not the problem's): that start is reported with the reason, the
    other start's branch is computed. Both are stored: a second run reads them back,
    the failed start's reason and simulation with them, and computes nothing."""
    follow = internal("snake branch")
    calls = []

    def first_fails(*args, **kwargs):
        calls.append(1)
        if len(calls) == 1:
            raise ValueError("problem.u0 is not a solution")
        return follow(*args, **kwargs)

    replace_internal(monkeypatch, "snake branch", first_fails)
    # k = 2 first: the branch that is computed is then k = 1's, on the shooting
    # options (its phase oscillator) whose programs the tests above compiled.
    kwargs = dict(continuation_options=jc.ContinuationOptions(ds=0.02, max_points=2),
                  start_options=jc.SimulationOptions(t_end=2000.0, transient=1500.0),
                  simulation_check=False, switch=False, out=tmp_path)
    found = jc.localized_branches(RING_OF_TWO, (2, 1), **kwargs)
    assert [b["label"] for b in found["summary"]["branches"]] == ["k=1"]
    (flagged,) = found["summary"]["not_periodic"]
    assert flagged["excited"] == 2 and "continuation failed" in flagged["reason"]

    def computes(*args, **kwargs):
        raise AssertionError("the stored starts are read back")

    replace_internal(monkeypatch, "snake starts", computes)
    again = jc.localized_branches(RING_OF_TWO, (2, 1), **kwargs)
    assert again["summary"]["not_periodic"] == found["summary"]["not_periodic"]
    assert list(again["datasets"]) == ["k=1"]


@pytest.mark.study
@pytest.mark.long
def test_a_switch_that_fails_is_reported_with_its_branch_point(branch_point, monkeypatch):
    """Where the step onto the other branch does not converge (`switch_branch` raises
    RuntimeError), the snake follows the orbits that deflation finds beside the
    branch point; where that finds none either, it keeps the branch point's v_d and
    the reason, for the followed branch's `failed_switches`, instead of dropping it
    silently."""
    problem, branch, point = branch_point

    def fails(*args, **kwargs):
        raise RuntimeError("switching did not converge")

    monkeypatch.setattr("jaxchain._bifurcation.branches.switch_branch", fails)
    switched = internal("snake switched branch")
    args = (SHOOTING_OF_TWO, problem, branch, point, jc.ContinuationOptions(max_points=2),
            jc.PseudoArclength())
    # deflation beside the branch point finds the other branch instead
    rescued = switched(*args, progress=False)
    assert rescued and all(b.switched_from == float(point.p) for b in rescued)
    monkeypatch.setattr("jaxchain._bifurcation.branches.switch_by_deflation",
                        lambda *a, **k: [])
    (failure,) = switched(*args, progress=False)
    assert failure.p == float(point.p) and failure.reason == (
        "switching did not converge; deflation beside it found no other orbit, "
        "nor a step along an axis of its symmetry")


def _pitchfork(symmetric: bool):
    """u = (a, b, c): the trivial branch a = b = 0, c = v_d meets a branch point at
    v_d = 1. With `symmetric`, G is equivariant under the rotations of the (a, b)
    plane (O(2)), so both a and b are critical there; else only a is."""
    def residual(u, p):
        a, b, c = u
        r2 = a**2 + b**2 if symmetric else a**2
        return jnp.stack([(p.v_d - 1) * a - a * r2,
                          (p.v_d - 1) * b - b * r2 if symmetric else b, c - p.v_d])
    return jc.ContinuationProblem(residual=residual, u0=jnp.array([0.0, 0.0, 1.0]),
                                  params=jc.ChainParams(n_osc=1, v_d=1.0))


@pytest.mark.parametrize("symmetric, critical", [(False, [[1, 0, 0, 0]]),
                                                 (True, [[1, 0, 0, 0], [0, 1, 0, 0]])])
def test_critical_directions_are_the_kernel_less_the_branch(symmetric, critical):
    """At the analytic branch point the kernel of [G_u, G_p] is the branch's tangent
    (0, 0, 1, 1)/sqrt 2 and the critical plane of (a, b) (O(2)-symmetric) or the
    line of a (no symmetry): `critical_directions` is an orthonormal basis of the
    latter, whatever the sign of the tangent given."""
    problem = _pitchfork(symmetric)
    z = jnp.array([0.0, 0.0, 1.0, 1.0])
    for sign in (1, -1):
        got = critical_directions(problem, z, sign * jnp.array([0.0, 0.0, 1.0, 1.0]))
        assert got.shape == (len(critical), 4)
        np.testing.assert_allclose(got @ got.T, np.eye(len(critical)), atol=1e-12)
        projector = np.asarray(critical, dtype=float)
        np.testing.assert_allclose(got @ projector.T @ projector, got, atol=1e-12)


@pytest.mark.study
@pytest.mark.numerics
def test_deflation_beside_the_branch_point_finds_keller_s_switched_orbit(branch_point):
    """`switch_by_deflation` (the followed orbit deflated at v_d = v_b -+ 0.002,
    shooting from it moved along the critical direction) finds the orbit that
    Keller's step and continuation reach at v_b - 0.002 (another route: the
    corrector along the kernel direction, then pseudo-arclength steps and shooting
    at that v_d), up to the swap of the two oscillators, to shooting's tolerance;
    the direction it returns points from the branch point to the orbit."""
    problem, branch, point = branch_point
    p = float(point.p) - 0.002
    found = switch_by_deflation(problem, branch, point, offset=0.002)
    below = [(new, t) for new, t in found if abs(float(new.value()) - p) < 1e-12]
    assert below
    new, tangent = below[0]
    assert start_residual(new) < 1e-6 and float(tangent[-1]) < 0
    _, switched = switched_on_ring_of_two(problem, branch, point, 0.01)
    ok = np.asarray(switched.converged)
    u = np.asarray(switched.u)[ok][np.argmin(np.abs(np.asarray(switched.p)[ok] - p))]
    keller = jc.periodic_orbit(jc.with_parameter(RING_OF_TWO, "v_d", p),
                               (u[:-1].reshape(2, -1), float(u[-1])), SHOOTING_OF_TWO)
    deflated = jc.periodic_orbit(jc.with_parameter(RING_OF_TWO, "v_d", p),
                                 (np.asarray(new.u0[:-1]).reshape(2, -1), float(new.u0[-1])),
                                 SHOOTING_OF_TWO)
    assert abs(float(deflated.period - keller.period)) < 1e-7
    # amplitudes from 4096 samples a period (Shooting.n_samples): the sampled
    # extremes of one orbit started at another phase (the swapped copy starts at the
    # other oscillator's turning point) differ by up to |x''| dt^2 / 8, below 1e-6
    np.testing.assert_allclose(np.sort(np.asarray(deflated.amplitudes)),
                               np.sort(np.asarray(keller.amplitudes)), atol=2e-6)
    assert abs(float(keller.amplitudes[0] - keller.amplitudes[1])) > 1e-4


def _s3_problem():
    """u in R^3, G_i = (v_d - 1) u_i + sum_j u_j + u_i^2 - u_i^3: equivariant under
    every permutation of (u_1, u_2, u_3) (S_3, the dihedral group of the triangle).
    The trivial branch u = 0 meets a branch point at v_d = 1 whose critical
    directions are the plane sum u = 0 (S_3's two-dimensional irreducible
    representation; the symmetric direction's eigenvalue there is 3)."""
    def residual(u, p):
        return (p.v_d - 1) * u + jnp.sum(u) + u**2 - u**3
    return jc.ContinuationProblem(residual=residual, u0=jnp.zeros(3),
                                  params=jc.ChainParams(n_osc=1, v_d=1.0))


def test_the_axes_of_a_symmetric_branch_point_are_the_lines_its_reflections_fix():
    """At the S_3-symmetric branch point the critical plane sum u = 0 holds three
    lines fixed by a transposition, (1, 1, -2) and its permutations, which the
    rotations map onto each other: `symmetric_directions` keeps one, whichever
    symmetry comes first, fixed by its transposition and normalised; Keller's step
    along it, to either side, lands on a branch that keeps that symmetry (two
    equal components), the same solution as the reduced two-unknown system
    solved by scipy at that v_d; the rotations alone fix no line."""
    from scipy.optimize import fsolve

    problem, z, tangent = _s3_problem(), jnp.array([0.0, 0.0, 0.0, 1.0]), jnp.eye(4)[3]
    perms = [[0, 1, 2], [1, 2, 0], [2, 0, 1], [1, 0, 2], [0, 2, 1], [2, 1, 0]]
    actions = [p + [3] for p in perms]
    axes = symmetric_directions(problem, z, tangent, actions)
    assert axes.shape == (1, 4)
    np.testing.assert_allclose(axes[0], np.array([-1.0, -1.0, 2.0, 0.0]) / np.sqrt(6),
                               atol=1e-12)
    assert symmetric_directions(problem, z, tangent, actions[:3]).shape == (0, 4)
    with pytest.raises(ValueError, match="permutations"):
        symmetric_directions(problem, z, tangent, [[0, 1, 1, 3]])
    branch = type("Branch", (), {"converged": np.ones(1, bool), "tangent": tangent[None]})
    point = type("Point", (), {"kind": "branch point", "z": z, "after": 0, "p": 1.0})
    for side in (1, -1):
        new, direction = jc.switch_branch(problem, branch, point, step=0.05, side=side,
                                          direction=axes[0])
        u, p = np.asarray(new.u0), float(new.value())
        assert abs(u[0] - u[1]) < 1e-10 and abs(u[0] - u[2]) > 1e-3
        np.testing.assert_allclose(direction, side * axes[0], atol=1e-15)

        def reduced(ac, p=p):
            a, c = ac
            s = 2 * a + c
            return [(p - 1) * a + s + a**2 - a**3, (p - 1) * c + s + c**2 - c**3]
        np.testing.assert_allclose(fsolve(reduced, u[[0, 2]], xtol=1e-13), u[[0, 2]],
                                   atol=1e-9)
        assert np.max(np.abs(problem.residual(jnp.asarray(u), new.params))) < 1e-9


def test_the_snake_switches_along_the_axes_of_the_orbit_s_symmetry():
    """The S_3 branch point above written as a ring of three's shooting unknowns
    (x, x', T) with v_d the parameter: x as u above, x' = 0, T = 1. The snake's
    step along the axes (`_switch_along_axes`: the isotropy of the state at the
    point, `chain_symmetries` of the ring of three, every permutation) lands,
    to both sides, on states that one transposition fixes and no rotation does,
    each a zero of G; a point whose state has no symmetry gives none."""
    def residual(u, p):
        x, v, t = u[:3], u[3:6], u[6]
        return jnp.concatenate([(p.v_d - 1) * x + jnp.sum(x) + x**2 - x**3, v,
                                jnp.atleast_1d(t - 1)])
    ring = jc.ChainParams(n_osc=3, v_d=1.0)
    problem = jc.ContinuationProblem(residual=residual, u0=jnp.zeros(7).at[6].set(1.0),
                                     params=ring)
    tangent = jnp.eye(8)[7]
    branch = type("Branch", (), {"converged": np.ones(1, bool), "tangent": tangent[None]})
    point = type("Point", (), {"kind": "branch point", "after": 0, "p": 1.0,
                               "z": jnp.zeros(8).at[6].set(1.0).at[7].set(1.0)})
    starts = internal("snake switch along axes")(problem, branch, point, jc.PseudoArclength())
    assert len(starts) == 2
    perms = np.asarray(chain_symmetries(ring))
    for new, direction in starts:
        x = np.asarray(new.u0[:3])
        assert np.max(np.abs(residual(new.u0, new.params))) < 1e-9
        fixed = [p for p in perms if np.allclose(x[p], x, atol=1e-10)]
        assert len(fixed) == 2 and np.ptp(x) > 1e-3  # the identity and a transposition
        assert abs(float(direction[-1])) < 1e-12  # the axis is orthogonal to the branch
    asymmetric = type("Point", (), {**vars(point), "z": point.z.at[:3].set([0.1, 0.2, 0.3])})
    assert internal("snake switch along axes")(problem, branch, asymmetric,
                                               jc.PseudoArclength()) == []


@pytest.mark.study
def test_the_distance_from_an_orbit_is_to_the_nearest_point_of_its_copies(
        ring_of_three_states):
    """`Deflation.distances` against the distance written out here: the closed
    polyline through the orbit's samples, each of its six copies built explicitly
    (y[:, perm]), every segment; the state near a copy of the orbit, near the orbit
    and far from both; its gradient against central differences."""
    simulated = ring_of_three_states  # the ring of three's states
    one = packed(simulated[1].y0, simulated[1].period)
    problem = jc.cycle_problem(simulated[1], SHOOTING_OF_THREE)
    operator = deflation(problem, [one], n_samples=64)
    samples = np.reshape(np.asarray(operator.curves[0]), (64, 2, 3))

    def written_out(u):
        y = np.asarray(u[:-1])
        best = np.inf
        for perm in np.asarray(chain_symmetries(RING_OF_THREE)):
            a = np.reshape(samples[:, :, perm], (64, 6))
            edge = np.roll(a, -1, axis=0) - a
            t = np.clip(np.sum((y - a) * edge, -1) / np.sum(edge**2, -1), 0.0, 1.0)
            best = min(best, np.min(np.sum((y - a - t[:, None] * edge) ** 2, -1)))
        return np.sqrt(best + (float(u[-1]) - float(one[-1])) ** 2)

    rng = np.random.default_rng(3)
    copy = jnp.concatenate([jnp.ravel(jnp.asarray(samples[17])[:, ::-1]), one[-1:] + 0.01])
    for u in (copy + 1e-4 * rng.standard_normal(7), one + 0.05 * rng.standard_normal(7),
              one + 2.0 * rng.standard_normal(7)):
        d = float(operator.distances(u)[0])
        assert abs(d - written_out(u)) < 1e-12 * max(d, 1.0)
        v, h = rng.standard_normal(7), 1e-6
        central = (written_out(u + h * v) - written_out(u - h * v)) / (2 * h)
        slope = float(jax.jvp(lambda w: operator.distances(w)[0], (u,), (jnp.asarray(v),))[1])
        assert abs(slope - central) < 1e-6 * max(abs(central), 1.0)


@pytest.mark.study
def test_symmetries_of_the_ring_and_the_deflation_operator_s_bad_arguments(
        ring_of_three_states):
    """The dihedral group on the homogeneous ring (2N distinct permutations), the
    identity alone on a free line; a clear error for bad arguments of the deflation
    operator (those of `distinct_orbits` and `localized_branches`, test_deflation.py)."""
    perms = np.asarray(chain_symmetries(jc.ChainParams(n_osc=5)))
    assert perms.shape == (10, 5) and {tuple(sorted(p)) for p in perms} == {tuple(range(5))}
    assert np.asarray(chain_symmetries(jc.ChainParams(n_osc=5, boundary="free"))).shape \
        == (1, 5)
    problem = jc.cycle_problem(ring_of_three_states[1], SHOOTING_OF_THREE)
    with pytest.raises(ValueError, match="n_samples"):
        deflation(problem, n_samples=4)


@pytest.mark.study
@pytest.mark.long
def test_a_start_that_is_not_periodic_is_deflated_from_its_eq8_state(tmp_path,
                                                                      monkeypatch):
    """A start whose simulated state is not periodic (here the one-site start, its
    orbit withheld) keeps its reason, and deflation still searches from its eq. (8)
    state (with the two-site start's orbit deflated, the problem borrowed from it):
    the orbit found is followed as "k=1 deflated 1". It is a periodic orbit for
    scipy, with one oscillator on the HALC, and no symmetric copy of the other
    branches' orbits."""
    starts = internal("snake starts")

    def one_site_not_periodic(*args, **kwargs):
        found = starts(*args, **kwargs)
        _, sim, _ = found[1]
        found[1] = (None, sim, "shooting did not converge: the simulated state is not "
                    "periodic")
        return found

    replace_internal(monkeypatch, "snake starts", one_site_not_periodic)
    found = jc.localized_branches(
        RING_OF_THREE, (2, 1), continuation_options=jc.ContinuationOptions(
            ds=0.02, ds_max=0.05, p_min=1.45, p_max=1.55, max_points=3),
        start_options=SETTLED, simulation_check=False, deflate=1, out=tmp_path)
    labels = list(found["datasets"])
    assert "k=1 deflated 1" in labels and "k=1" not in labels and labels[0] == "k=2"
    assert [n["excited"] for n in found["summary"]["not_periodic"]] == [1]
    at = {}
    for label in labels:
        ds = found["datasets"][label]
        i = int(np.argmin(np.abs(ds["v_d"].values - 1.5)))
        at[label] = (ds["u"].values[i], int(ds["n_halc"].values[i]))
    u, n_halc = at.pop("k=1 deflated 1")
    assert scipy_return(u) < 1e-6 and n_halc == 1
    assert all(copies_distance(other, u) > 1e-2 for other, _ in at.values())


@pytest.mark.study
def test_a_deflated_orbit_on_a_branch_already_followed_is_reported_not_followed(
        tmp_path, monkeypatch, ring_of_three_states):
    """Deflation's orbits replaced by two known ones: the two-site state rotated by
    one oscillator (a symmetric copy: on the start's own branch) and the one-site
    state (another branch). The copy is reported on "k=2" and not followed; the
    one-site state is followed as "k=2 deflated 1", one oscillator on the HALC at
    the start's v_d. A third solution of deflation, from which shooting did not
    converge, is neither. Read back, the report is the same, and a run resumed
    with a further start deflates from it every orbit the first run's deflation
    knew: the start's own orbit and the three solutions, to the last bit."""
    simulated = ring_of_three_states  # the ring of three's states
    two = simulated[2]
    rotated = jnp.roll(jnp.asarray(two.y0), 1, axis=1)
    phase = int(np.argmax(np.roll(np.asarray(two.amplitudes), 1)))
    copy = jc.periodic_orbit(RING_OF_THREE, (rotated, float(two.period)),
                             SHOOTING_OF_THREE.with_phase_oscillator(phase))
    assert bool(copy.converged)
    one = (simulated[1], int(np.argmax(np.asarray(simulated[1].amplitudes))))
    # deflation's solutions stand apart from the shot orbits (phase conditions differ)
    given = [(o, m, jnp.append(jnp.ravel(o.y0), o.period) + 1e-3)
             for o, m in [(copy, phase), one]]
    given.append((None, 0, given[0][2] + 0.5))
    replace_internal(monkeypatch, "snake deflated orbits",
                     lambda orbits, params, found, count, stored: {2: given})
    kwargs = dict(continuation_options=jc.ContinuationOptions(
        ds=0.02, ds_max=0.05, p_min=1.45, p_max=1.55, max_points=3),
        start_options=SETTLED, simulation_check=False, deflate=2, out=tmp_path)
    found = jc.localized_branches(RING_OF_THREE, (2,), **kwargs)
    assert list(found["datasets"]) == ["k=2", "k=2 deflated 1"]
    (repeat,) = found["summary"]["deflated_on_followed"]
    assert repeat["start"] == "k=2" and repeat["on"] == "k=2" and repeat["n_halc"] == 2
    ds = found["datasets"]["k=2 deflated 1"]
    assert int(ds["n_halc"].values[int(np.argmin(np.abs(ds["v_d"].values - 1.5)))]) == 1

    def computes(*args, **kwargs):
        raise AssertionError("the stored branches are read back")

    replace_internal(monkeypatch, "snake starts", computes)
    again = jc.localized_branches(RING_OF_THREE, (2,), **kwargs)
    assert list(again["datasets"]) == ["k=2", "k=2 deflated 1"]
    assert again["summary"]["deflated_on_followed"] == [repeat]
    # resumed with the one-site start: its deflation (replaced by a spy) is given the
    # orbits the first run's deflation knew, read back from the stored records
    seen = []
    replace_internal(monkeypatch, "snake starts",
                     lambda *args: {1: (None, {}, "not periodic (replaced)")})
    replace_internal(monkeypatch, "snake deflated orbits",
                     lambda orbits, params, found, count, stored: seen.append(stored) or {})
    jc.localized_branches(RING_OF_THREE, (2, 1), **kwargs)
    ((own, *deflated),) = seen
    assert all(np.array_equal(a, u) for a, (_, _, u) in zip(deflated, given, strict=True))
    start = found["datasets"]["k=2"]  # its first point: its start orbit, corrected again
    i = int(np.argmin(np.abs(start["v_d"].values - 1.5)))
    np.testing.assert_allclose(own, start["u"].values[i], rtol=0,
                               atol=10 * jc.Shooting().newton_tol)


@pytest.mark.study
@pytest.mark.numerics
def test_a_resumed_run_deflates_the_orbits_of_the_starts_it_read_back(tmp_path,
                                                                       monkeypatch):
    """`localized_branches(deflate=1)` from the two- and the one-site start, then again
    with the one-site start's files removed, as after a run stopped once its first
    start was stored: deflation from the one-site start has every orbit deflated
    that it had in the whole run (the two-site start's own and the orbit deflation
    found from it, read back from the two-site start's record, to the last bit),
    and the resumed run ends with the whole run's branches."""
    real, seen = internal("snake deflation"), []

    def spy(problem, start, known, **kwargs):
        seen.append([np.asarray(u) for u in known])
        return real(problem, start, known, **kwargs)

    replace_internal(monkeypatch, "snake deflation", spy)
    kwargs = dict(continuation_options=jc.ContinuationOptions(
        ds=0.02, ds_max=0.05, p_min=1.45, p_max=1.55, max_points=3),
        start_options=SETTLED, simulation_check=False, deflate=1, out=tmp_path)
    whole = jc.localized_branches(RING_OF_THREE, (2, 1), **kwargs)
    whole_known = seen[-1]
    seen.clear()
    for path in tmp_path.glob("branch_k1*.nc"):
        path.unlink()
    resumed = jc.localized_branches(RING_OF_THREE, (2, 1), **kwargs)
    (known,) = seen  # deflation from the one-site start alone
    assert len(known) == len(whole_known) == 3
    # the same orbits: the one-site start's own is shot again in the resumed run
    # (Newton's tolerance 1e-9)
    assert all(min(copies_distance(u, v) for v in known) < 1e-6 for u in whole_known)
    # the two read back (the two-site start's own orbit and deflation's solution from
    # it) are the whole run's to the last bit
    assert sum(any(np.array_equal(u, v) for v in known) for u in whole_known) >= 2
    assert list(resumed["datasets"]) == list(whole["datasets"])
    # orbits of one residual, each to Newton's tolerance (1e-9, shooting and the
    # continuation's corrector alike) from its root
    tol = 10 * jc.Shooting().newton_tol
    for label, ds in whole["datasets"].items():
        np.testing.assert_allclose(resumed["datasets"][label]["u"].values, ds["u"].values,
                                   rtol=0, atol=tol, err_msg=label)
