"""Continuation of the single oscillator's limit cycles from the Hopf point through
the fold, the fold's extended system and its parameter derivatives, against the
non-smooth existence limit and finite differences; the fold located by bisection
along the branch against the extended (Moore-Spence) system."""

import json
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxchain as jc
from helpers import BISTABLE_RATIO_VALUES, BISTABLE_XI_VALUES


class _Point(eqx.Module):
    stable: jnp.ndarray


@pytest.fixture(scope="module")
def branch():
    orbit = jc.hopf_cycle(jc.ChainParams(n_osc=1))
    problem = jc.cycle_problem(orbit)
    found = jc.continuation(problem, options=jc.ContinuationOptions(
        ds=0.01, ds_max=0.1, p_min=1.0, p_max=2.5, max_points=50))
    return problem, found, jc.fold_point(problem, found)


@pytest.mark.numerics
@pytest.mark.study
def test_branch_leaves_the_hopf_point_upwards_and_turns_at_a_fold(branch):
    _, found, _ = branch
    p = np.asarray(found.p)[np.asarray(found.converged)]
    hopf = float(jc.hopf_vd_analytic(jc.ChainParams(n_osc=1)))
    assert p[0] > hopf and p[1] > p[0]  # subcritical: the cycles lie where SS is stable
    assert len(found.folds) == 1
    i = found.folds[0]
    assert p[i] >= p[:i].max() - 1e-12 or p[i + 1] >= p.max() - 1e-12
    assert p[-1] < p.max() - 1e-3  # it came back down on the other side
    # stability changes at the fold: a Floquet multiplier crosses +1
    assert found.stability_changes == (i,) or found.stability_changes == (i + 1,)
    critical = np.abs(np.asarray(found.records.critical_multiplier))
    assert np.all(critical[:i] > 1) and np.all(critical[i + 2:] < 1)
    assert not bool(found.records.stable[0]) and bool(found.records.stable[-1])
    trivial = np.asarray(found.records.multipliers)[np.arange(p.size), found.records.trivial]
    assert np.max(np.abs(trivial - 1)) < 1e-6


@pytest.mark.numerics
@pytest.mark.study
def test_fold_is_near_the_nonsmooth_existence_limit(branch):
    _, found, fold = branch
    assert bool(fold.converged)
    assert float(fold.p) >= float(np.max(np.asarray(found.p)[np.asarray(found.converged)]))
    limit = jc.stick_slip_existence_limit()
    assert abs(float(fold.p) - limit) < 0.01
    multipliers = np.sort(np.abs(np.asarray(fold.record.multipliers)))[::-1]
    assert np.all(np.abs(multipliers[:2] - 1) < 1e-3)  # trivial and critical at +1


@pytest.mark.numerics
@pytest.mark.study
def test_bisection_along_the_branch_finds_the_fold_of_the_extended_system(branch):
    """On the single oscillator's branch from the Hopf point, the fold located by
    bisection on dp/ds agrees with the Moore-Spence fold to 1e-6."""
    problem, found, reference = branch
    folds = [b for b in jc.locate_bifurcations(problem, found) if b.kind == "fold"]
    assert len(folds) == 1
    assert abs(float(folds[0].p) - float(reference.p)) < 1e-6
    assert abs(complex(folds[0].multiplier) - 1) < 1e-3


@pytest.mark.numerics
@pytest.mark.parametrize("where, value", [("xi", 0.05), ("mu_st", 1.0)])
@pytest.mark.study
def test_fold_derivative_against_finite_differences(branch, where, value):
    problem, _, fold = branch
    start = jnp.concatenate([fold.u, fold.p[None], fold.null_vector])
    def fold_at(v, guess):
        moved = problem.with_params(jc.with_parameter(problem.params, where, v))
        return jc.solve_fold(moved, guess)

    value = jnp.asarray(value, dtype=float)
    solution, ok = fold_at(value, start)
    assert bool(ok)
    # forward mode through the implicit function (optimistix's ImplicitAdjoint)
    _, derivative = jax.jvp(lambda v: fold_at(v, solution)[0], (value,),
                            (jnp.ones_like(value),))
    n = problem.u0.size
    h = 1e-5
    plus, ok_plus = fold_at(value + h, solution + h * derivative)
    minus, ok_minus = fold_at(value - h, solution - h * derivative)
    assert bool(ok_plus) and bool(ok_minus)
    fd = (plus[n] - minus[n]) / (2 * h)
    assert abs(float(derivative[n]) - float(fd)) < 1e-4 * abs(float(fd))

    # reverse mode: the implicit function theorem's tangent transposes (a
    # forward-mode pass through diffrax's loop would not)
    def fold_vd(v):
        return fold_at(v, solution)[0][n]

    reverse = float(jax.grad(fold_vd)(jnp.asarray(value)))
    assert abs(reverse - float(derivative[n])) < 1e-10 * abs(reverse)


@pytest.fixture(scope="module")
def default_curves(branch):
    """The fold and Hopf curves of `jaxchain boundaries` on its default grids."""
    problem, _, fold = branch
    start = jnp.concatenate([fold.u, fold.p[None], fold.null_vector])
    mu_d = float(problem.params.friction.mu_d)
    return {"xi": jc.boundary_curves(problem, start, "xi", BISTABLE_XI_VALUES),
            "mu_st": jc.boundary_curves(problem, start, "mu_st",
                                        mu_d * np.asarray(BISTABLE_RATIO_VALUES))}


@pytest.mark.numerics
@pytest.mark.slow
@pytest.mark.parametrize("where", ["xi", "mu_st"])
@pytest.mark.study
def test_every_default_fold_converges_near_the_existence_limit(branch, default_curves, where):
    problem, _, fold = branch
    curves = default_curves[where]
    assert bool(jnp.all(curves.converged))
    values = np.asarray(curves.values)
    single = problem.params
    limit = np.array([jc.stick_slip_existence_limit(jc.with_parameter(single, where, v))
                      for v in values])
    fold_vd = np.asarray(curves.fold_vd)
    # the smoothed fold comes slightly before the non-smooth grazing limit
    assert np.all(np.abs(fold_vd - limit) < 0.01) and np.all(fold_vd < limit)
    # Hopf point: v0 ln((mu_st - mu_d) / (2 xi v0)), and its derivative
    xi = values if where == "xi" else float(single.xi)
    mu_st = values if where == "mu_st" else float(single.friction.mu_st)
    np.testing.assert_allclose(curves.hopf_vd, 0.5 * np.log((mu_st - 0.5) / xi), atol=1e-10)
    d_hopf = -0.5 / xi if where == "xi" else 0.5 / (mu_st - 0.5)
    np.testing.assert_allclose(curves.d_hopf, d_hopf, rtol=1e-8)
    # the curve passes through the one-parameter fold, and the derivative along the
    # curve is that of finite differences between its points
    value = {"xi": single.xi, "mu_st": single.friction.mu_st}[where]
    at = int(np.argmin(np.abs(values - float(value))))
    assert abs(fold_vd[at] - float(fold.p)) < 1e-9
    d_fold = np.asarray(curves.d_fold)
    centred = (fold_vd[2:] - fold_vd[:-2]) / (values[2:] - values[:-2])
    assert np.all(np.sign(centred) == np.sign(d_fold[1:-1]))
    if where == "xi":
        # more damping: both edges fall, the fold faster, so the window narrows
        assert np.all(np.diff(fold_vd) < 0) and np.all(d_fold < np.asarray(curves.d_hopf))
    assert np.all(fold_vd > np.asarray(curves.hopf_vd))


@pytest.mark.numerics
@pytest.mark.slow
@pytest.mark.study
def test_fold_curve_is_robust_to_a_perturbed_start(branch, default_curves):
    problem, _, fold = branch
    start = np.concatenate([fold.u, fold.p[None], fold.null_vector])
    rng = np.random.default_rng(0)
    perturbed = start * (1 + 1e-6 * rng.choice([-1.0, 1.0], start.size))
    reference = default_curves["xi"]
    values = np.asarray(reference.values)[[2, 3, 4]]
    curves = jc.boundary_curves(problem, jnp.asarray(perturbed), "xi", values)
    assert bool(jnp.all(curves.converged))
    np.testing.assert_allclose(curves.fold_vd, np.asarray(reference.fold_vd)[[2, 3, 4]],
                               rtol=0, atol=1e-8)


@pytest.mark.numerics
def test_continuation_on_an_analytic_fold_records_failures():
    # u^2 + v_d - 2 = 0: a fold at v_d = 2, u = 0; stable where u > 0
    problem = jc.ContinuationProblem(
        residual=lambda u, p: u**2 + p.v_d - 2, u0=jnp.array([1.0]),
        params=jc.ChainParams(n_osc=1, v_d=1.0),
        describe=lambda u, p: _Point(stable=u[0] > 0))
    found = jc.continuation(problem, options=jc.ContinuationOptions(
        ds=0.1, ds_max=0.3, max_points=40, p_min=0.0))
    assert found.folds and found.stability_changes
    fold = jc.fold_point(problem, found)
    assert abs(float(fold.p) - 2) < 1e-12 and abs(float(fold.u[0])) < 1e-7
    failing = jc.continuation(problem, jc.PseudoArclength(newton_steps=1),
                              jc.ContinuationOptions(ds=0.5, ds_min=0.1, ds_max=0.5))
    assert not bool(jnp.all(failing.converged)) and failing.stop == jc.Status.newton_failed
    assert bool(failing.converged[0])  # what was found is kept
    with pytest.raises(ValueError, match="not a solution"):
        jc.continuation(eqx.tree_at(lambda pr: pr.u0, problem, jnp.array([3.0])))


@pytest.mark.numerics
def test_a_failed_hopf_solve_is_nan_never_a_number():
    """`hopf_vd` (the traced Hopf point of the two-parameter curves) against the
    analytic v0 ln((mu_st - mu_d) / (2 xi v0)) and its derivative -v0/xi in xi; and
    NaN, with a NaN derivative, where Newton's method cannot succeed: with
    mu_st = mu_d the growth rate is -xi at every belt speed (there is no root), and
    from a guess of v_d = 800 the exponential law's slope exp(-v_d/v0) underflows to
    zero in float64. A guess that is no belt speed is refused, naming it."""
    one = jc.ChainParams(n_osc=1)
    def hopf_and_derivative(params):
        return jax.jvp(lambda xi: jc.hopf_vd(jc.with_parameter(params, "xi", xi)),
                       (jnp.asarray(0.05),), (jnp.asarray(1.0),))

    hopf, d_xi = hopf_and_derivative(one)
    assert abs(float(hopf) - 0.5 * np.log(10)) < 1e-10
    assert abs(float(d_xi) + 0.5 / 0.05) < 1e-8
    value, derivative = hopf_and_derivative(jc.ChainParams(n_osc=1, mu_st=0.5))
    assert np.isnan(float(value)) and np.isnan(float(derivative))
    assert np.isnan(float(jc.hopf_vd(one, guess=800.0)))
    with pytest.raises(ValueError, match="guess"):
        jc.hopf_vd(one, guess=-50.0)


@pytest.mark.numerics
@pytest.mark.study
def test_boundaries_command_json_and_figures(tmp_path, capsys):
    """`jaxchain boundaries` end to end on one oscillator (no ring, no simulation
    dots), on two damping ratios and one friction ratio: the Hopf point against its
    closed form, every fold beside the non-smooth existence limit there, and the
    design checked by simulation on both sides of it. It runs here, after the
    tests above, because it continues the same limit cycles: this process has
    compiled their programs already."""
    code = jc.main(["boundaries", "--json", "--no-ring", "--no-simulation", "--xi-values",
                 "0.05,0.06", "--ratio-values", "2.0", "--no-progress", "--out",
                 str(tmp_path)])
    assert code == 0
    out = json.loads(capsys.readouterr().out)
    assert set(out["outputs"]) == {"bifurcation_single.png", "bistable_region.png",
                                   "boundaries.json"}
    assert abs(out["hopf_vd"] - 0.5 * np.log(10)) < 1e-6
    assert abs(out["fold_vd"] - jc.stick_slip_existence_limit()) < 0.01
    assert out["subcritical"] is True and out["eps"] == float(jc.Smoothed().eps)
    # every point of both curves has a fold, beside the non-smooth limit there
    for curve in (out["xi_curve"], out["ratio_curve"]):
        fold, limit = np.array(curve["fold_vd"]), np.array(curve["existence_limit_nonsmooth"])
        assert np.all(np.abs(fold - limit) < 0.01)
    assert abs(out["xi_curve"]["existence_limit_nonsmooth"][1]
               - jc.stick_slip_existence_limit(jc.ChainParams(n_osc=1, xi=0.06))) < 1e-9
    # the design's answer, checked by simulation on both sides of it
    design = out["design"]
    assert abs(design["window"] - design["target_window"]) < 1e-6
    check = design["simulation_check"]
    assert check["below"]["n_halc"] == 1 and check["above"]["amplitude"] < 1e-3
    for name, path in out["outputs"].items():
        if name.endswith(".png"):
            assert Path(path).stat().st_size > 10_000


class _Switching(eqx.Module):
    """A record whose critical multiplier jumps from 0.5 to 2 where v_d passes 1.3,
    and whose count of zero multipliers (stick phases) drops from 1 to 0 there
    unless `keep_zero`."""

    multipliers: jnp.ndarray
    trivial: jnp.ndarray
    zero_multipliers: jnp.ndarray
    stable: jnp.ndarray

    @property
    def critical_multiplier(self):
        return self.multipliers[..., 1]


@pytest.mark.parametrize("keep_zero, kind", [(False, "sliding"), (True, "grazing")])
def test_a_jumping_multiplier_is_a_discontinuity_induced_bifurcation(keep_zero, kind):
    """On the line u = v_d, records built to jump at v_d = 1.3: the change of stability
    is located within the bisection's resolution and named by the segment structure
    (the exact model's sliding or grazing), never a multiplier crossing (the located
    multiplier, 0.5, is nowhere near the unit circle)."""
    def describe(u, p):
        beyond = p.v_d > 1.3
        m = jnp.where(beyond, 2.0, 0.5) + 0j
        zeros = jnp.where(beyond & (not keep_zero), 0, 1)
        return _Switching(multipliers=jnp.stack([1.0 + 0j, m]), trivial=jnp.asarray(0),
                          zero_multipliers=zeros, stable=~beyond)

    problem = jc.ContinuationProblem(residual=lambda u, p: u - p.v_d, u0=jnp.array([1.0]),
                                     params=jc.ChainParams(n_osc=1, v_d=1.0),
                                     describe=describe)
    branch = jc.continuation(problem, options=jc.ContinuationOptions(
        ds=0.1, ds_max=0.1, max_points=8))
    (point,) = jc.locate_bifurcations(problem, branch)
    assert point.kind == kind and abs(float(point.p) - 1.3) < 1e-6


def test_a_branch_point_where_the_corrector_fails_around_it_is_interpolated():
    """On the curve u = (v_d - 1)^2, records whose critical multiplier exp(v_d - 1)
    crosses +1 at v_d = 1, and a corrector that fails within 2e-3 of it, as it does
    beside the branch points of the ring of 20 (there [G_u, G_p] is nearly singular):
    the branch point is located within 1e-5 of v_d = 1, the zero of the linear
    interpolation between the converged points either side (its error here is
    |f''/ 2 f'| (2e-3)^2 = 2e-6), not at the edge of the failures 2e-3 away."""
    def residual(u, p):
        return jnp.where(jnp.abs(p.v_d - 1) < 2e-3, jnp.nan, u - (p.v_d - 1) ** 2)

    def describe(u, p):
        m = jnp.exp(p.v_d - 1) + 0j
        return _Switching(multipliers=jnp.stack([1.0 + 0j, m]), trivial=jnp.asarray(0),
                          zero_multipliers=jnp.asarray(0), stable=jnp.abs(m) < 1)

    problem = jc.ContinuationProblem(residual=residual, u0=jnp.array([0.2025]),
                                     params=jc.ChainParams(n_osc=1, v_d=0.55),
                                     describe=describe)
    branch = jc.continuation(problem, options=jc.ContinuationOptions(
        ds=0.1, ds_max=0.1, max_points=10))
    (point,) = jc.locate_bifurcations(problem, branch)
    assert point.kind == "branch point" and abs(float(point.p) - 1) < 1e-5
    assert abs(float(point.z[-1]) - 1) >= 2e-3  # a converged trial, outside the failures
