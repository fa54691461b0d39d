"""Intentional mistuning by gradient (issue 26, item 3) on a ring of four: the fold
of the single-site state at another oscillator, reached through the ring's
symmetry and followed along the pattern, against the fold found from scratch on
the mistuned ring; the gradient of each fold against central finite
differences."""

import jax.numpy as jnp
import numpy as np
import pytest

import jaxchain as jc
from jaxchain._studies.mistuning.pattern_design import pattern_deviations
from helpers import internal

design_problems = internal("mistuning design problems")
pattern_folds = internal("pattern folds")

RING = jc.ChainParams(n_osc=4, v_d=1.5)
BUDGET = 0.004
THETA = np.array([0.4, -0.2, 0.1, 0.3])


@pytest.fixture(scope="module")
def followed():
    problem, solutions, homogeneous = design_problems(RING, BUDGET)
    folds, grads, sols, ok = pattern_folds(problem, solutions, np.zeros(4), THETA, BUDGET,
                                           False)
    assert ok.all()
    return problem, folds, grads, sols, homogeneous


@pytest.mark.numerics
@pytest.mark.study
def test_followed_fold_is_the_mistuned_ring_s_own_fold(followed):
    """The fold of the state at oscillator 1 (0-based), followed from the
    homogeneous ring through the pattern and the ring's symmetry, is the fold that
    `localized_fold` finds from scratch on the mistuned ring (simulation,
    shooting, continuation, Moore-Spence), to Newton's tolerance. From scratch on
    the ring turned by one oscillator (delta_n -> delta_(n-1)), where that state
    sits at oscillator 2, the site of the design's own problem: a ring is the same
    chain whichever oscillator is numbered first, and the solve compiles the
    programs of the problem's site once."""
    _, folds, _, _, homogeneous = followed
    delta = np.asarray(pattern_deviations(jnp.asarray(THETA), BUDGET, 4, False))
    turned = jc.ChainParams(n_osc=4, v_d=1.5, stiffness=1 + np.roll(delta, 1))
    fold, _ = jc.localized_fold(turned, 2)
    assert abs(float(fold.p) - folds[1]) < 1e-7
    assert abs(folds[1] - homogeneous) > 1e-5  # the pattern moved it


@pytest.mark.numerics
@pytest.mark.study
def test_fold_gradients_match_finite_differences(followed):
    """d fold_j / d theta by implicit differentiation (forward mode through
    optimistix's ImplicitAdjoint) against central differences of the fold solved
    again at theta +- h e_k (h = 1e-3: truncation ~ h^2 f''' and Newton's
    tolerance 1e-9 / h, both far below the gradients)."""
    problem, folds, grads, sols, _ = followed
    h = 1e-3
    for k in range(4):
        e = np.eye(4)[k] * h
        plus = pattern_folds(problem, sols, THETA, THETA + e, BUDGET, False)[0]
        minus = pattern_folds(problem, sols, THETA, THETA - e, BUDGET, False)[0]
        np.testing.assert_allclose(grads[:, k], (plus - minus) / (2 * h), atol=1e-6,
                                   rtol=1e-3)
    assert np.abs(grads).max() > 1e-4  # the folds do move with the stiffness


@pytest.mark.numerics
def test_pattern_keeps_budget_and_mean():
    theta = jnp.array([3.0, -0.5, 0.1, 2.0])
    d = np.asarray(pattern_deviations(theta, 0.05, 8, zero_mean=True))
    assert abs(d.mean()) < 1e-15 and np.abs(d).max() <= 0.05 + 1e-15
    np.testing.assert_array_equal(d[:4], d[4:])
    free = np.asarray(pattern_deviations(theta, 0.05, 4, zero_mean=False))
    np.testing.assert_allclose(free, 0.05 * np.tanh(np.asarray(theta)))


def test_bad_design_settings():
    with pytest.raises(ValueError, match="budget"):
        design_problems(RING, 1.5)
    with pytest.raises(ValueError, match="homogeneous ring"):
        design_problems(jc.mistune(RING, 0.01, 0), 0.01)
    with pytest.raises(ValueError, match="sense"):
        jc.intentional_mistuning(RING, sense="up")
