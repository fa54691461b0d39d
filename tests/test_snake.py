"""The snake on a small ring: shooting from simulated chain states, Floquet
multipliers against their closed-form estimate, stable ends against direct simulation,
the stored branches read back, and the command line."""

import json

import jax.numpy as jnp
import numpy as np
import pytest
import xarray as xr
from scipy.integrate import solve_ivp

import jaxchain as jc

from helpers import (assert_usage_error, internal, internal_module, reference_rhs,
                     replace_internal)

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
