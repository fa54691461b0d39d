"""Branch switching at the symmetry-breaking branch point of the ring of two: the
two-site state (both oscillators on the HALC, equal amplitudes) meets a Floquet
multiplier +1 without a fold; the switched branch breaks the symmetry and is the
same branch whatever the step off the branch point; a branch point on an unstable
branch of the ring of three, against shooting at fixed v_d. All through public names:
the building blocks of switching (critical and symmetric directions, deflation
beside the branch point, the steps along a symmetry's axes) and the snake's
switching, provoked through its private functions, are test_snake.py's."""

import dataclasses

import numpy as np
import pytest

import jaxchain as jc

from helpers import (RING_OF_TWO, SETTLED, SHOOTING_OF_TWO, snake_start, start_residual,
                     switched_on_ring_of_two)

RING, SHOOTING = RING_OF_TWO, SHOOTING_OF_TWO
# The fixture `branch_point`, the two-site state continued to its first branch point,
# is tests/conftest.py's: the tests of the snake's switching share it (test_snake.py).


@pytest.mark.study
def test_switched_branch_breaks_the_symmetry_and_converges_under_refinement(branch_point):
    """Off the branch point by 0.02 and by 0.01 in arclength: each switched branch
    has unequal amplitudes, their difference growing away from the branch point
    (a pitchfork: ~ sqrt(|v_d - v_b|)), while the followed branch keeps them
    equal; at v_d 0.002 below the branch point both switched branches give, by
    shooting from their nearest point, the same orbit to 1e-7."""
    problem, branch, point = branch_point
    followed = np.asarray(branch.records.amplitudes)
    assert np.max(np.abs(followed[:, 0] - followed[:, 1])) < 1e-6
    target = jc.with_parameter(RING, "v_d", float(point.p) - 0.002)
    orbits = []
    for step in (0.02, 0.01):
        new, switched = switched_on_ring_of_two(problem, branch, point, step)
        assert start_residual(new) < 1e-6  # a solution, off the followed branch
        amplitudes = np.asarray(switched.records.amplitudes)
        split = np.abs(amplitudes[:, 0] - amplitudes[:, 1])
        assert np.all(split > 1e-5) and split[-1] > 10 * split[0]
        p = np.asarray(switched.p)[np.asarray(switched.converged)]
        assert p.min() < float(target.v_d)  # reaches the comparison point
        u = np.asarray(switched.u)[np.asarray(switched.converged)]
        near = u[np.argmin(np.abs(p - float(target.v_d)))]
        orbits.append(jc.periodic_orbit(target, (near[:-1].reshape(2, -1), float(near[-1])),
                                        SHOOTING))
    a, b = orbits
    assert abs(float(a.amplitudes[0] - a.amplitudes[1])) > 1e-4
    np.testing.assert_allclose(np.asarray(a.y0), np.asarray(b.y0), atol=1e-7)
    assert abs(float(a.period - b.period)) < 1e-7


@pytest.mark.study
def test_switching_needs_a_branch_point(branch_point):
    problem, branch, point = branch_point
    with pytest.raises(ValueError, match="step"):
        jc.switch_branch(problem, branch, point, step=0.0)
    fold = dataclasses.replace(point, kind="fold")
    with pytest.raises(ValueError, match="branch point"):
        jc.switch_branch(problem, branch, fold)


@pytest.mark.study
@pytest.mark.long
def test_a_branch_point_on_an_unstable_branch_is_where_shooting_at_fixed_v_d_crosses():
    """The exact one-site branch of the ring of three, continued down from v_d 1.38
    through its fold at 1.3749 onto the unstable sheet above it, meets a branch
    point there: on an orbit unstable already, so no stability changes, and only
    the sign of the bordered determinant det [[G_u, G_p], [t^T]]
    (`Branch.branch_points`) sees it. Against shooting at fixed v_d, no
    continuation: at v_b - delta and v_b + delta, from the branch's orbits either
    side, the sign of prod (mu_i - 1) over the non-trivial Floquet multipliers (of
    det(M - I) on them) differs, for delta = 2e-3 and 2e-4; and the multiplier
    nearest +1 approaches it as delta shrinks (here a complex pair meets the real
    axis at +1 and leaves it as a real pair, one multiplier either side of +1)."""
    ring = jc.ChainParams(n_osc=3, v_d=1.38)
    orbit, phase = snake_start(ring, 1, method=jc.Shooting.from_simulations(jc.Exact()),
                               options=SETTLED)
    shooting = jc.Shooting(jc.Exact().for_orbits(), phase_oscillator=phase)
    problem = jc.cycle_problem(orbit, shooting)
    branch = jc.continuation(problem, options=jc.ContinuationOptions(
        ds=0.02, ds_max=0.1, p_min=1.3, p_max=1.45, max_points=12, direction=-1))
    (point,) = [b for b in jc.locate_bifurcations(problem, branch) if b.kind == "branch point"]
    assert point.after not in branch.stability_changes
    assert not bool(np.asarray(branch.stable)[point.after + 1])  # unstable already
    assert abs(complex(point.multiplier) - 1) < 1e-4
    ok = np.flatnonzero(np.asarray(branch.converged))
    v_b = float(point.p)

    def at(side: int, delta: float) -> tuple[float, float]:
        """(sign of prod (mu_i - 1), min |mu_i - 1|) of the orbit at v_b + delta."""
        u = np.asarray(branch.u)[ok[side]]
        shot = jc.periodic_orbit(jc.with_parameter(ring, "v_d", v_b + delta),
                                 (u[:-1].reshape(2, -1), float(u[-1])), shooting)
        assert bool(shot.converged)
        m = np.delete(np.asarray(shot.multipliers), int(shot.trivial))
        return float(np.sign(np.prod(m - 1).real)), float(np.min(np.abs(m - 1)))

    far = [at(point.after, -2e-3), at(point.after + 1, 2e-3)]
    near = [at(point.after, -2e-4), at(point.after + 1, 2e-4)]
    assert far[0][0] == -far[1][0] and near[0][0] == -near[1][0]
    assert all(n[1] < f[1] and n[1] < 1e-2 for n, f in zip(near, far))
