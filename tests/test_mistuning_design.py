"""Intentional mistuning by gradient (issue 26, item 3) on a ring of four, through
`jc.intentional_mistuning`: the fold of the single-site state at each oscillator,
reached through the ring's symmetry and followed along the pattern, against the
fold found from scratch on the mistuned ring (`jc.localized_fold`); the design's
gradient against central finite differences of its objective computed from those
folds; the pattern within its budget."""

import numpy as np
import pytest
from scipy.special import logsumexp, softmax

import jaxchain as jc

RING = jc.ChainParams(n_osc=4, v_d=1.5)
#: The budget of the design: its starting pattern (seed 0, theta about 0.03) moves
#: the folds by up to 4e-5 in v_d.
BUDGET = 0.02
#: The objective's temperature (`intentional_mistuning`'s default).
TEMPERATURE = 2e-3
#: The oscillator (0-based) of the single-site state whose fold the design solves
#: (that of `localized_orbit` on a ring of four): every other site's fold is that
#: state's on the ring turned, so that the solves from scratch compile once.
SITE = 2


def _pattern(theta, budget=BUDGET):
    """The deviations of the design variables theta, mean free (`zero_mean=False`),
    written here as `intentional_mistuning` documents them: budget tanh(theta)."""
    return budget * np.tanh(np.asarray(theta, dtype=float))


def _fold(delta, j: int) -> float:
    """The fold of the single-site state at oscillator j of the ring of stiffness
    1 + delta, from scratch (`localized_fold`: simulation, shooting, continuation,
    Moore-Spence), solved on the ring turned so that the state sits at `SITE`: a
    ring is the same chain whichever oscillator is numbered first."""
    turned = jc.ChainParams(n_osc=4, v_d=1.5, stiffness=1 + np.roll(delta, SITE - j))
    fold, _ = jc.localized_fold(turned, SITE)
    return float(fold.p)


@pytest.fixture(scope="module")
def design():
    """The design's first iterate (no Adam step), mean free: every site's fold
    followed from the homogeneous ring to the starting pattern, and the gradient
    there. Mean free, so that the folds' derivatives do not cancel in the
    objective's (with the mean kept, a ring's average fold hardly moves with the
    pattern)."""
    jc.configure()
    return jc.intentional_mistuning(RING, budget=BUDGET, zero_mean=False, steps=0,
                                    progress=False)


@pytest.mark.numerics
@pytest.mark.study
@pytest.mark.long
def test_followed_fold_is_the_mistuned_ring_s_own_fold(design):
    """The fold of the state at oscillator 1 (0-based), followed from the
    homogeneous ring through the pattern and the ring's symmetry, is the fold that
    `localized_fold` finds from scratch on the mistuned ring, to Newton's
    tolerance; the pattern moved it."""
    folds = np.asarray(design.folds)
    assert abs(_fold(np.asarray(design.pattern), 1) - folds[1]) < 1e-7
    assert abs(folds[1] - design.homogeneous_edge) > 1e-5  # the pattern moved it
    assert design.edge == folds.max()


@pytest.mark.numerics
@pytest.mark.study
@pytest.mark.long
def test_the_design_gradient_matches_finite_differences(design):
    """d objective / d theta (`MistuningDesign.gradient`: implicit differentiation
    of every fold, forward mode through optimistix's ImplicitAdjoint, weighted by
    the smooth maximum) against central differences of the objective, the smooth
    maximum t log sum exp(fold_j / t) of the four folds, each solved from scratch
    (`_fold`) at the pattern of theta +- h e_k (h = 1e-3: truncation ~ h^2 f''' and
    the folds' Newton tolerance, 1e-9, over h, both far below the gradient). At t =
    2e-3 and folds 6e-5 apart every fold weighs about a quarter, so that a wrong
    derivative of any one shows. The pattern is that of theta as documented."""
    theta = np.asarray(design.theta)
    np.testing.assert_allclose(np.asarray(design.pattern), _pattern(theta), rtol=0,
                               atol=1e-15)

    def objective(th):
        folds = [_fold(_pattern(th), j) for j in range(4)]
        return TEMPERATURE * logsumexp(np.asarray(folds) / TEMPERATURE)

    # every fold weighs in the objective
    assert np.all(softmax(np.asarray(design.folds) / TEMPERATURE) > 0.2)
    h = 1e-3
    fd = [(objective(theta + h * e) - objective(theta - h * e)) / (2 * h)
          for e in np.eye(4)]
    np.testing.assert_allclose(np.asarray(design.gradient), fd, atol=1e-6, rtol=1e-3)
    assert np.abs(design.gradient).max() > 1e-4  # the folds do move with the stiffness


@pytest.mark.numerics
@pytest.mark.study
@pytest.mark.long
def test_pattern_keeps_budget_and_mean():
    """With the mean kept (the default), the design's pattern keeps the ring's mean
    stiffness and the budget, from a start (seed 1) whose budget tanh(theta) has a
    mean of its own."""
    theta = 0.05 * np.random.default_rng(1).standard_normal(4)  # the design's start
    assert abs(_pattern(theta).mean()) > 1e-5
    design = jc.intentional_mistuning(RING, budget=BUDGET, steps=0, seed=1, progress=False)
    d = np.asarray(design.pattern)
    assert abs(d.mean()) < 1e-15 and np.abs(d).max() <= BUDGET + 1e-15
    np.testing.assert_allclose(d, _pattern(theta) - _pattern(theta).mean(), rtol=0,
                               atol=1e-15)


def test_bad_design_settings():
    with pytest.raises(ValueError, match="budget"):
        jc.intentional_mistuning(RING, budget=1.5, progress=False)
    with pytest.raises(ValueError, match="homogeneous ring"):
        jc.intentional_mistuning(jc.mistune(RING, 0.01, 0), budget=0.01, progress=False)
    with pytest.raises(ValueError, match="sense"):
        jc.intentional_mistuning(RING, sense="up")
