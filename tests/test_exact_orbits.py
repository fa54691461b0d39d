"""Periodic orbits of the exact switch model by shooting on the exact engine (issue
56, item 1): the single oscillator's stick-slip cycle against the independent
scipy cycle, its exact Floquet multipliers, and Newton's convergence from
perturbed starts."""

import json

import jax.numpy as jnp
import numpy as np
import pytest

import jaxchain as jc
from helpers import (BISTABLE_RATIO_VALUES, BISTABLE_XI_VALUES, scipy_slip_arc,
                     scipy_stick_slip_cycle)

ONE = jc.ChainParams(n_osc=1, v_d=1.5, xi=0.05)
#: Shooting on the exact engine at the reference's tolerances (Tsit5, rtol = atol = 1e-12).
EXACT = jc.Shooting(jc.Exact().for_orbits())


@pytest.fixture(scope="module")
def guess():
    """A turning point x' = 0 near the cycle's maximum, from a simulation, and the
    scipy cycle's (amplitude, period)."""
    obs = jc.simulate(ONE, jnp.array([[2.0], [0.0]]),
                      engine=jc.Exact(jc.NonsmoothOptions.reference(t_end=100.0, transient=50.0)))
    return float(obs.x_max_halves[1, 0]), scipy_stick_slip_cycle(ONE)


@pytest.mark.study
@pytest.mark.numerics
@pytest.mark.parametrize("dx, period_factor", [(0.01, 1.02), (-0.05, 0.97), (0.08, 1.04)])
def test_exact_stick_slip_cycle_from_perturbed_starts_is_the_scipy_cycle(guess, dx,
                                                                         period_factor):
    """Shooting on the exact engine from starts perturbed in x(0) and T converges to
    the cycle that scipy finds event by event (`scipy_stick_slip_cycle`): the
    period to 1e-9 (the flow at rtol 1e-12), the amplitude to 1e-6 (read from 4096
    samples of the period: a maximum between samples is missed by at most
    A (pi/4096)^2 / 2 = 5e-7). Its Floquet multipliers are exact: the trivial one
    is 1 and the other 0, since one stick phase per period forgets the state (the
    Poincare map x(0) -> x(T) on x' = 0 is constant near the orbit, its derivative
    zero)."""
    x_max, (amplitude, period) = guess
    orbit = jc.periodic_orbit(ONE, (jnp.array([[x_max + dx], [0.0]]),
                                    period * period_factor), EXACT)
    assert bool(orbit.converged)
    np.testing.assert_allclose(float(orbit.period), period, rtol=1e-9)
    np.testing.assert_allclose(float(orbit.amplitudes[0]), amplitude, rtol=1e-6)
    multipliers = np.asarray(orbit.multipliers)
    assert abs(multipliers[int(orbit.trivial)] - 1) < 1e-8
    assert int(orbit.zero_multipliers) == 1 and np.abs(multipliers).min() < 1e-9
    assert int(orbit.n_halc) == 1 and bool(orbit.stable)


@pytest.mark.numerics
@pytest.mark.study
def test_the_exact_cycle_s_stick_phase_is_the_scipy_stick(guess):
    """The stick phase of the single oscillator's exact stick-slip cycle, read from
    the exact engine's switch log over its orbit (`Exact.stick_phases`), is the stick of
    the scipy cycle: from the return to the belt speed back to the stick exit
    point, (x_exit - x_return) / v_d, to the period's 1e-9 (relative)."""
    x_max, (_, period) = guess
    orbit = jc.periodic_orbit(ONE, (jnp.array([[x_max], [0.0]]), period), EXACT)
    arc = scipy_slip_arc(ONE)
    stick = (arc.y[0, 0] - arc.y[0, -1]) / ONE.v_d
    phases = EXACT.engine.stick_phases(ONE, orbit.y0, orbit.period)
    assert abs(phases[0] - stick) < 1e-9 * period
    # steady sliding has no stick phase
    sliding = jc.ChainParams(n_osc=1, v_d=3.0, xi=0.05)
    y = jc.Exact().steady_sliding(sliding)
    assert np.isinf(EXACT.engine.stick_phases(sliding, y, 6.0)).all()


def test_sliding_location_needs_exact_orbits_with_a_stick_phase():
    problem = jc.ContinuationProblem(residual=lambda u, p: u, u0=jnp.zeros(3), params=ONE)
    with pytest.raises(ValueError, match="cycle_problem"):
        jc.locate_sliding(problem, jnp.zeros(4))
    with pytest.raises(ValueError, match="held"):
        jc.NonsmoothOptions(held=(-1,))
    with pytest.raises(ValueError, match="period"):
        EXACT.engine.stick_phases(ONE, jnp.zeros((2, 1)), 0.0)


def test_exact_shooting_refuses_bad_input_in_one_line():
    with pytest.raises(ValueError, match="y0 must have shape"):
        jc.periodic_orbit(ONE, (jnp.zeros((2, 2)), 6.0), EXACT)
    with pytest.raises(ValueError, match="period"):
        jc.periodic_orbit(ONE, (jnp.zeros((2, 1)), -1.0), EXACT)
    with pytest.raises(ValueError, match="adjoint"):
        jc.Shooting(jc.Exact(jc.NonsmoothOptions.reference(adjoint="reverse")))
    with pytest.raises(ValueError, match="damped_steps"):
        jc.Shooting(jc.Exact().for_orbits(), damped_steps=-1)


@pytest.mark.numerics
@pytest.mark.study
@pytest.mark.long
def test_the_damped_newton_method_reaches_a_weakly_unstable_orbit_from_farther():
    """The ring of eight's five-site orbit at v_d 1.4 (eq. (8) with five sites,
    found by the snake from its simulation) is unstable by a real multiplier 1.034
    and has a complex pair 1.007 beside the trivial 1. Its state rounded to three
    digits is the start of shooting. From that orbit's state moved by 0.05
    (normal, seeds 4 to 7), Newton's method alone fails for some seeds (6 and 7
    when this test was written; 2 of seeds 0 to 7); with the damped Newton method
    after it (the default) every one converges to the same orbit: period to 1e-9,
    state to 1e-7."""
    ring = jc.ChainParams(n_osc=8, v_d=1.4)
    method = EXACT.with_phase_oscillator(2)
    near = jnp.array([[0.566, 0.726, 2.118, 1.409, -0.377, -0.824, -0.245, 0.67],
                      [0.063, 0.317, 0.0, -1.289, -1.088, -0.014, -1.226, -0.31]])
    orbit = jc.periodic_orbit(ring, (near, 6.292), method)
    assert int(orbit.n_halc) == 5 and not bool(orbit.stable)
    for seed in range(4, 8):
        moved = orbit.y0 + 0.05 * np.random.default_rng(seed).normal(size=(2, 8))
        again = jc.periodic_orbit(ring, (moved, orbit.period), method)
        assert abs(float(again.period - orbit.period)) < 1e-9, seed
        np.testing.assert_allclose(np.asarray(again.y0), np.asarray(orbit.y0), atol=1e-7)


@pytest.mark.study
@pytest.mark.numerics
@pytest.mark.long
def test_smoothed_multipliers_approach_the_exact_ones_as_eps_falls(guess):
    """Two oscillators in phase on a ring (the coupling idle: each is the single
    oscillator's cycle): the exact Floquet multipliers are 1 (trivial), two zeros
    (each oscillator's stick forgets its velocity) and one real multiplier of the
    anti-phase perturbation. The smoothed model's multipliers, from shooting at
    eps = 1e-2, 1e-3 and 1e-4 (an independent flow and solver), approach it: the
    distance falls by at least 5 per decade of eps (it falls as eps) and is
    within 2e-4 at eps = 1e-4."""
    x_max, (_, period) = guess
    pair = jc.ChainParams(n_osc=2, v_d=1.5, xi=0.05)
    exact = jc.periodic_orbit(pair, (jnp.array([[x_max, x_max], [0.0, 0.0]]), period), EXACT)
    multipliers = np.asarray(exact.multipliers)
    assert int(exact.zero_multipliers) == 2
    assert abs(multipliers[int(exact.trivial)] - 1) < 1e-8
    critical = multipliers[np.argmax(np.where(np.arange(4) == int(exact.trivial), 0,
                                              np.abs(multipliers)))]
    distances = []
    for eps in (1e-2, 1e-3, 1e-4):
        smoothed = jc.periodic_orbit(pair, (exact.y0, float(exact.period)),
                                     jc.Shooting(jc.Smoothed(eps=eps).for_orbits()))
        distances.append(abs(complex(smoothed.critical_multiplier) - critical))
    assert distances[0] > 5 * distances[1] > 25 * distances[2]
    assert distances[2] < 2e-4


@pytest.mark.study
@pytest.mark.numerics
@pytest.mark.long
def test_exact_cycles_continued_in_v_d_are_the_scipy_cycles_up_to_the_existence_limit(guess):
    """Pseudo-arclength continuation of the exact stick-slip cycle in v_d
    (`cycle_problem` on the exact engine): at every converged point below the existence limit
    (`stick_slip_existence_limit`, independent: an arc integrated by diffrax) the
    period is scipy's cycle's to 1e-8 (0.02 below the limit and lower), the cycle
    stable with its non-trivial multiplier 0; the cycle exists up to 1e-3 below the
    limit, where its slip arc comes to graze v_rel = 0 (the branch leaves the range
    there, it does not fail)."""
    x_max, (_, period) = guess
    orbit = jc.periodic_orbit(ONE, (jnp.array([[x_max], [0.0]]), period), EXACT)
    limit = jc.stick_slip_existence_limit(ONE)
    branch = jc.continuation(jc.cycle_problem(orbit, EXACT), jc.PseudoArclength(),
                             jc.ContinuationOptions(ds=0.05, ds_max=0.1, p_min=1.0,
                                                    p_max=limit - 1e-3, max_points=30))
    p = np.asarray(branch.p)[np.asarray(branch.converged)]
    # the cycle exists all the way: the run ends by leaving the range, not by failing
    assert branch.stop == jc.Status.left_parameter_range and p.max() > limit - 1e-2
    # scipy's event finds a return that grazes the belt speed unreliably (it misses
    # it within 1e-3 of the limit and takes the next): compare 0.02 below it
    compared = np.flatnonzero(p < limit - 0.02)
    assert compared.size >= 4
    for k in compared[np.linspace(0, compared.size - 1, 4).astype(int)]:
        chain = jc.ChainParams(n_osc=1, v_d=float(p[k]), xi=0.05)
        np.testing.assert_allclose(float(branch.records.period[k]),
                                   scipy_stick_slip_cycle(chain)[1], rtol=1e-8)
    assert np.asarray(branch.stable).all()
    assert np.abs(np.asarray(branch.records.multipliers)).min(axis=1).max() < 1e-9
    # where the branch ends: the grazing point, by Newton's method on its defining
    # condition (x' = v_d and x'' = 0 at the end of the slip arc) from the branch's
    # last point and from two points further down, is the closed-form limit (its
    # bisection to 1e-10, Newton's tolerance 1e-12, both arcs at rtol 1e-12)
    for near in (p.max(), limit - 0.02, limit - 0.2):
        grazing = jc.stick_slip_grazing(ONE, "v_d", near=float(near))
        assert bool(grazing.converged) and abs(float(grazing.value) - limit) < 1e-8, near


@pytest.fixture(scope="module")
def followed_past_the_limit(guess):
    """The exact cycle followed in v_d from 1.5 towards 0.05 beyond the existence
    limit (`follow_branch`, one way): the branch ends (its corrector fails) at a
    sliding point, and goes on through it from the branch's last orbits onto the
    cycle without stick (`past_sliding_start`), down to the Hopf point, where it is
    cut."""
    x_max, (_, period) = guess
    orbit = jc.periodic_orbit(ONE, (jnp.array([[x_max], [0.0]]), period), EXACT)
    limit = jc.stick_slip_existence_limit(ONE)
    options = jc.ContinuationOptions(ds=0.05, ds_max=0.1, p_min=1.0, p_max=limit + 0.05,
                                     max_points=30)
    return jc.follow_branch(orbit, EXACT, options, directions=(1,))


@pytest.fixture(scope="module")
def through_the_limit(followed_past_the_limit):
    """The two continuations of `followed_past_the_limit`, each (problem, branch,
    bifurcations): up to the sliding point, and on past it."""
    return list(followed_past_the_limit.pieces)


@pytest.mark.numerics
@pytest.mark.study
def test_the_followed_branch_ends_at_a_sliding_point_and_is_cut_at_the_hopf_point(
        followed_past_the_limit, through_the_limit):
    """`follow_branch` goes through the sliding point where the stick-slip
    continuation's corrector fails (the first piece stops `newton_failed` with a
    sliding point among its last two orbits), onto a second piece, and cuts the
    branch at the Hopf point (stop "hopf"): its bifurcations are the sliding point at
    the closed-form existence limit and the Hopf point at its closed form (both to
    1e-6), in the order of the branch, and every kept point lies between them or
    before the sliding point."""
    followed = followed_past_the_limit
    (_, first, bifs), _ = through_the_limit
    ok = np.asarray(first.converged)
    assert first.stop.name == "newton_failed"
    assert [b for b in bifs if b.kind == "sliding" and b.after >= int(ok.sum()) - 2]
    assert followed.stops == {"end": "hopf"}
    kinds = [b.kind for b in followed.bifurcations]
    assert kinds[-1] == "Hopf" and "sliding" in kinds
    sliding = next(b for b in followed.bifurcations if b.kind == "sliding")
    hopf = followed.bifurcations[-1]
    limit = float(jc.stick_slip_existence_limit(ONE))
    closed_form = float(jc.hopf_vd_analytic(ONE))
    assert abs(sliding.p - limit) < 1e-6 and abs(hopf.p - closed_form) < 1e-6
    assert followed.p.max() < limit and followed.p.min() > closed_form


@pytest.fixture(scope="module")
def past_the_limit(through_the_limit):
    """The exact cycle's problem, and its branch continued in v_d from 1.5 towards
    0.05 beyond the existence limit (`continuation`: the first piece)."""
    problem, branch, _ = through_the_limit[0]
    return problem, branch


@pytest.mark.numerics
@pytest.mark.study
def test_the_branch_continued_past_the_existence_limit_meets_a_sliding_point_there(
        past_the_limit):
    """Continued beyond the existence limit, the exact branch meets a sliding
    bifurcation: `locate_bifurcations` (the chains' method, nothing of the single
    oscillator's closed form) puts the stick phase's duration d vanishing there
    (`locate_sliding`, the secant method on d^2 = 0) at the closed-form limit
    (`stick_slip_existence_limit`: an arc integrated by diffrax, bisected to 1e-10).
    For every friction law of jaxchain the slip force at v_rel -> 0 is the static
    bound, so the slip arc meets v_rel = 0 tangentially
    (x'' = 0 there: grazing) exactly where the force needed to stick is mu_st, where
    the stick phase it begins has no duration: the grazing point of the cycle is
    that sliding point (issue 56, acceptance 1 asks 1e-6)."""
    problem, branch = past_the_limit
    limit = jc.stick_slip_existence_limit(ONE)
    # past the limit the corrector fails, or steps onto the unstable cycle without
    # stick that the stick-slip cycle meets there: either way one sliding point
    (end,) = [b for b in jc.locate_bifurcations(problem, branch) if b.kind == "sliding"]
    assert end.width < 1e-8 and abs(float(end.p) - limit) < 1e-8


@pytest.mark.numerics
@pytest.mark.study
def test_past_the_sliding_point_the_branch_is_the_cycle_without_stick_down_to_hopf(
        through_the_limit):
    """Through the sliding point at the existence limit the continuation
    (`past_sliding_start`: the oscillator held in slip, on the side where it never
    reaches the belt speed: its relative velocity keeps its sign over the start's
    orbit, by the exact engine's flow) goes on as the cycle without stick that the
    subcritical Hopf point of steady sliding sends out: below the limit, as the stick-slip cycle (the branch
    turns at the sliding point), every orbit unstable and with no stick phase, down
    to the closed-form Hopf point (`hopf_vd_analytic`). There the branch passes
    through steady sliding (its amplitude changes sign, and v_d turns):
    `locate_bifurcations` names that turn a Hopf point, not a fold, at the zero of
    the energy (linear in v_d to leading order), to 1e-6. The sliding point lies at
    the closed-form limit (`stick_slip_existence_limit`) to 1e-6; up to the Hopf
    point (beyond it lie the same cycles half a period on) every orbit of the two
    pieces past the sliding point lies between the two, v_d falling along them."""
    (problem, _, bifs), (new, past, past_bifs) = through_the_limit
    (end,) = [b for b in bifs if b.kind == "sliding"]
    assert float(new.value()) < float(end.p) and float(past.tangent[0, -1]) < 0
    # the start's orbit (no stick: the exact flow held in slip or not is the same),
    # 512 samples of its period: x' - v_d keeps the sign it has at t = 0
    at = jc.with_parameter(ONE, "v_d", float(new.value()))
    y0, period = jnp.reshape(new.u0[:-1], (2, 1)), float(new.u0[-1])
    ys = EXACT.engine.flow(at, y0, period * jnp.linspace(0.0, 1.0, 513)[1:])
    v_rel = np.concatenate([[float(y0[1, 0])], np.asarray(ys)[:, 1, 0]]) - float(at.v_d)
    assert np.min(np.sign(v_rel[0]) * v_rel) > 0
    ok = np.asarray(past.converged)
    assert ok.sum() > 20 and not np.asarray(past.stable)[ok].any()
    for u, p in list(zip(np.asarray(past.u)[ok], np.asarray(past.p)[ok]))[::6]:
        y0, period = jnp.reshape(u[:-1], (2, 1)), float(u[-1])
        phases = EXACT.engine.stick_phases(jc.with_parameter(ONE, "v_d", float(p)), y0,
                                           period)
        assert np.isinf(phases).all()
    (hopf,) = past_bifs
    amplitude = np.asarray(past.records.amplitudes)[:, 0]
    closed_form = float(jc.hopf_vd_analytic(ONE))
    assert hopf.kind == "Hopf" and amplitude[hopf.after] < 0.1
    assert abs(float(hopf.p) - closed_form) < 1e-6
    limit = float(jc.stick_slip_existence_limit(ONE))
    assert abs(float(end.p) - limit) < 1e-6
    first = through_the_limit[0][1]
    first_p = np.asarray(first.p)[np.asarray(first.converged)]
    beyond = np.concatenate([first_p[end.after + 1:], np.asarray(past.p)[ok][:hopf.after + 1]])
    assert np.all(np.diff(beyond) < 0) and beyond.max() < limit and beyond.min() > closed_form


@pytest.mark.numerics
@pytest.mark.study
def test_the_sliding_point_from_the_branch_s_own_orbits_needs_no_trial_beside_them(
        past_the_limit):
    """`locate_sliding` seeded with the branch's orbits nearest the limit (the
    secant method starts from them) puts the sliding point at the closed-form limit
    to 1e-8 with its first trials at +- 10 in v_d, where no orbit exists: the seeds
    alone lead it there. Beside a sliding point where the branch turns (the
    stick-slip cycle meets the cycle without stick), a trial predicted from one orbit
    can converge to the other cycle; the seeds avoid such trials."""
    problem, branch = past_the_limit
    limit = jc.stick_slip_existence_limit(ONE)
    ok = np.asarray(branch.converged)
    zs = np.concatenate([np.asarray(branch.u), np.asarray(branch.p)[:, None]], axis=1)[ok]
    sticking = zs[(zs[:, -1] < limit) & np.asarray(branch.records.n_halc == 1)]
    nearest = sticking[np.argsort(limit - sticking[:, -1])[:3]]
    point = jc.locate_sliding(problem, nearest[0], delta=10.0, seeds=nearest[1:])
    assert point.converged and abs(float(point.p) - limit) < 1e-8


@pytest.mark.numerics
@pytest.mark.study
def test_sliding_curves_in_xi_and_mu_st_are_the_existence_limits(past_the_limit):
    """The sliding point followed in a second parameter (`sliding_curve`, natural
    continuation with `locate_sliding` at each value: the chains' method) over the
    landed fold-curve grid (xi 0.03 ... 0.10; mu_st/mu_d 1.6 ... 2.4), where the
    limit moves from 2.66 to 1.06, is the closed-form existence limit at every
    point (issue 56, acceptance 1 asks 1e-5)."""
    problem, branch = past_the_limit
    ok = np.asarray(branch.converged)
    stick = np.asarray(branch.records.zero_multipliers) > 0  # stick-slip cycles
    z = jnp.concatenate([branch.u, branch.p[:, None]], axis=1)[ok][stick]
    point = jc.locate_sliding(problem, z[int(np.argmax(z[:, -1]))])
    mu_d = float(ONE.friction.mu_d)
    for where, values in (("xi", np.asarray(BISTABLE_XI_VALUES)),
                          ("mu_st", mu_d * np.asarray(BISTABLE_RATIO_VALUES))):
        curve = jc.sliding_curve(problem, point, where, values)
        assert np.asarray(curve.converged).all() and float(np.max(curve.step)) < 1e-8, where
        closed = [jc.stick_slip_existence_limit(jc.with_parameter(ONE, where, v))
                  for v in values]
        np.testing.assert_allclose(np.asarray(curve.p), closed, rtol=0, atol=1e-8,
                                   err_msg=where)
    with pytest.raises(ValueError, match="values"):
        jc.sliding_curve(problem, point, "xi", [0.05, 0.04])
    with pytest.raises(ValueError, match="margin"):
        jc.sliding_curve(problem, point, "xi", [0.05], margin=0.0)


@pytest.mark.numerics
@pytest.mark.study
def test_grazing_curves_against_xi_and_the_friction_ratio_are_the_existence_limits():
    """The two-parameter curves of grazing (`grazing_curve`, natural continuation of
    the grazing point) over the landed fold-curve grid (xi 0.03 ... 0.10 at the
    default mu_st; mu_st/mu_d 1.6 ... 2.4 at xi 0.05) against the closed-form
    existence limit at every point; the default point is on both curves."""
    point = jc.stick_slip_grazing(ONE, "v_d", near=1.7)
    mu_d = float(ONE.friction.mu_d)
    for where, values in (("xi", np.asarray(BISTABLE_XI_VALUES)),
                          ("mu_st", mu_d * np.asarray(BISTABLE_RATIO_VALUES))):
        curve = jc.grazing_curve(point, where, values)
        limits = [jc.stick_slip_existence_limit(jc.with_parameter(ONE, where, v))
                  for v in values]
        assert np.asarray(curve.converged).all()
        np.testing.assert_allclose(np.asarray(curve.value), limits, rtol=0, atol=1e-8)


@pytest.mark.numerics
@pytest.mark.parametrize("where", ["xi", "mu_st"])
@pytest.mark.study
def test_grazing_slope_is_the_derivative_of_the_existence_limit(where):
    """`grazing_slope` (the implicit function theorem on the defining condition)
    against central differences of the closed-form existence limit (h = 1e-5, the
    limit bisected to 1e-12: noise 1e-7, truncation 1e-10 of the slope)."""
    point = jc.stick_slip_grazing(ONE, "v_d", near=1.7)
    q, h = float({"xi": ONE.xi, "mu_st": ONE.friction.mu_st}[where]), 1e-5
    limits = [jc.stick_slip_existence_limit(jc.with_parameter(ONE, where, q + s * h),
                                            lower=float(point.value) - 0.1, tol=1e-12)
              for s in (1, -1)]
    fd = (limits[0] - limits[1]) / (2 * h)
    assert abs(jc.grazing_slope(point, where) - fd) < 1e-6 * abs(fd)


@pytest.mark.numerics
@pytest.mark.study
def test_boundaries_command_with_the_exact_engine_reports_grazing(tmp_path, capsys):
    """`jaxchain boundaries --engine exact`: the Hopf point (closed form) and the
    grazing point, found from steady sliding's Hopf point without a start, in the
    smoothed run's keys (fold_vd and the curves), each grazing value the closed-form
    existence limit there."""
    assert jc.main(["boundaries", "--engine", "exact", "--json", "--xi-values", "0.05,0.06",
                    "--ratio-values", "1.8,2.0", "--no-progress", "--out", str(tmp_path)]) == 0
    out = json.loads(capsys.readouterr().out)
    assert set(out["outputs"]) == {"bistable_region.png", "boundaries.json"}
    assert out["engine"] == "exact" and out["boundary"] == "grazing"
    assert abs(out["hopf_vd"] - 0.5 * np.log(10)) < 1e-12
    assert abs(out["fold_vd"] - jc.stick_slip_existence_limit(ONE)) < 1e-8
    for key, where, scale in (("xi_curve", "xi", 1.0), ("ratio_curve", "mu_st", 0.5)):
        curve = out[key]
        values = curve["xi" if where == "xi" else "mu_st/mu_d"]
        limits = [jc.stick_slip_existence_limit(jc.with_parameter(ONE, where, v * scale))
                  for v in values]
        np.testing.assert_allclose(curve["fold_vd"], limits, rtol=0, atol=1e-8)
    assert out["ratio_curve"]["d_fold_vd"][1] == pytest.approx(out["d_fold_vd_d_ratio"],
                                                              rel=1e-9)


def test_grazing_needs_a_stick_slip_cycle_to_start_from():
    with pytest.raises(jc.ValidationError, match="n_osc = 1"):
        jc.stick_slip_grazing(jc.ChainParams(n_osc=2), "v_d")
    with pytest.raises(ValueError, match="no stick-slip cycle"):
        jc.stick_slip_grazing(ONE, "v_d", near=2.5)
    with pytest.raises(jc.ValidationError, match="give near"):
        jc.stick_slip_grazing(ONE, "xi")
