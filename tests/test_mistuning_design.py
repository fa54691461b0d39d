"""Intentional mistuning by gradient (issue 26, item 3) on a ring of four: the
single-site folds moved along the ring by symmetry, and the gradient of each fold
in the design variables against central finite differences of the fold itself."""

import jax.numpy as jnp
import numpy as np
import pytest

import jaxchain as jc
from jaxchain._mistuning.design import design_problems, pattern_deviations, pattern_folds

RING = jc.ChainParams(n_osc=4, v_d=1.5)
BUDGET = 0.02


@pytest.fixture(scope="module")
def problems():
    return design_problems(RING, 2, BUDGET)


def test_the_moved_folds_are_the_same_fold(problems):
    """On the homogeneous ring the single-site states at the two kinds of site are
    one state moved by the ring's symmetry: Newton's method from the moved solution
    stays at the same fold belt speed (to its tolerance)."""
    probs, sols, sites, homogeneous = problems
    assert sites == [2, 3]
    folds, _, _, ok = pattern_folds(probs, sols, np.zeros(2), BUDGET, True)
    assert ok.all()
    np.testing.assert_allclose(folds, homogeneous, atol=1e-7)


def test_fold_gradients_match_finite_differences(problems):
    """d fold_j / d theta by implicit differentiation (forward mode through
    optimistix's ImplicitAdjoint) against central differences of the fold solved
    again at theta +- h e_k (h = 1e-3: truncation error h^2 f''' ~ 1e-7, Newton's
    tolerance 1e-9 / h ~ 1e-6, both well below the gradients ~ 1e-2)."""
    probs, sols, _, _ = problems
    theta = np.array([0.4, -0.2])
    folds, grads, sols, ok = pattern_folds(probs, sols, theta, BUDGET, False)
    assert ok.all()
    h = 1e-3
    for k in range(2):
        e = np.eye(2)[k] * h
        plus = pattern_folds(probs, sols, theta + e, BUDGET, False)[0]
        minus = pattern_folds(probs, sols, theta - e, BUDGET, False)[0]
        fd = (plus - minus) / (2 * h)
        np.testing.assert_allclose(grads[:, k], fd, atol=2e-5, rtol=1e-3)
    assert np.abs(grads).max() > 1e-3  # the folds do move with the stiffness


def test_pattern_keeps_budget_and_mean():
    theta = jnp.array([3.0, -0.5, 0.1, 2.0])
    d = np.asarray(pattern_deviations(theta, 0.05, 8, zero_mean=True))
    assert abs(d.mean()) < 1e-15 and np.abs(d).max() <= 0.05 + 1e-15
    np.testing.assert_array_equal(d[:4], d[4:])
    free = np.asarray(pattern_deviations(theta, 0.05, 4, zero_mean=False))
    np.testing.assert_allclose(free, 0.05 * np.tanh(np.asarray(theta)))


def test_bad_design_settings():
    with pytest.raises(ValueError, match="period"):
        design_problems(RING, 3, BUDGET)
    with pytest.raises(ValueError, match="budget"):
        design_problems(RING, 2, 1.5)
    with pytest.raises(ValueError, match="homogeneous ring"):
        design_problems(jc.mistune(RING, 0.01, 0), 2, BUDGET)
