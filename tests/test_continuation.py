"""Continuation of the single oscillator's limit cycles from the Hopf point through
the fold, the fold's extended system and its parameter derivatives, against the
non-smooth existence limit and finite differences."""

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest

import jaxchain as jc


class _Point(eqx.Module):
    stable: jnp.ndarray


@pytest.fixture(scope="module")
def branch():
    orbit = jc.hopf_cycle(jc.ChainParams(n_osc=1))
    problem = jc.limit_cycle_problem(orbit)
    found = jc.continuation(problem, options=jc.ContinuationOptions(
        ds=0.01, ds_max=0.1, p_min=1.0, p_max=2.5, max_points=50))
    return problem, found, jc.fold_point(problem, found)


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


def test_fold_is_near_the_nonsmooth_existence_limit(branch):
    _, found, fold = branch
    assert bool(fold.converged)
    assert float(fold.p) >= float(np.max(np.asarray(found.p)[np.asarray(found.converged)]))
    limit = jc.stick_slip_existence_limit()
    assert abs(float(fold.p) - limit) < 0.01
    multipliers = np.sort(np.abs(np.asarray(fold.record.multipliers)))[::-1]
    assert np.all(np.abs(multipliers[:2] - 1) < 1e-3)  # trivial and critical at +1


@pytest.mark.parametrize("where, value", [(lambda p: p.xi, 0.05), (lambda p: p.mu_st, 1.0)])
def test_fold_derivative_against_finite_differences(branch, where, value):
    problem, _, fold = branch
    start = jnp.concatenate([fold.u, fold.p[None], fold.null_vector])
    solution, derivative, ok = jc.fold_and_derivative(problem, where, value, start)
    assert bool(ok)
    n = problem.u0.size
    h = 1e-5
    plus, _, ok_plus = jc.fold_and_derivative(problem, where, value + h, solution + h * derivative)
    minus, _, ok_minus = jc.fold_and_derivative(problem, where, value - h,
                                                solution - h * derivative)
    assert bool(ok_plus) and bool(ok_minus)
    fd = (plus[n] - minus[n]) / (2 * h)
    assert abs(float(derivative[n]) - float(fd)) < 1e-4 * abs(float(fd))


def test_boundary_curves_in_xi(branch):
    problem, _, fold = branch
    start = jnp.concatenate([fold.u, fold.p[None], fold.null_vector])
    curves = jc.boundary_curves(problem, start, lambda p: p.xi, [0.045, 0.05, 0.06])
    assert bool(jnp.all(curves.converged))
    xi = np.asarray(curves.values)
    np.testing.assert_allclose(curves.hopf_vd, 0.5 * np.log(0.5 / xi), atol=1e-10)
    np.testing.assert_allclose(curves.d_hopf, -0.5 / xi, rtol=1e-8)
    assert abs(float(curves.fold_vd[1]) - float(fold.p)) < 1e-9
    # more damping: both edges fall, the fold faster, so the bistable window narrows
    fold, d_fold = np.asarray(curves.fold_vd), np.asarray(curves.d_fold)
    assert np.all(np.diff(fold) < 0) and np.all(d_fold < np.asarray(curves.d_hopf))
    assert np.all(fold > np.asarray(curves.hopf_vd))


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
    assert not bool(jnp.all(failing.converged)) and "ds_min" in failing.stop
    assert bool(failing.converged[0])  # what was found is kept
    with pytest.raises(ValueError, match="not a solution"):
        jc.continuation(eqx.tree_at(lambda pr: pr.u0, problem, jnp.array([3.0])))
