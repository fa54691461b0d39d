"""Branch switching at the symmetry-breaking branch point of the ring of two: the
two-site state (both oscillators on the HALC, equal amplitudes) meets a Floquet
multiplier +1 without a fold; the switched branch breaks the symmetry and is the
same branch whatever the step off the branch point."""

import dataclasses

import jax.numpy as jnp
import numpy as np
import pytest

import jaxchain as jc
from jaxchain._bifurcation.deflation import chain_symmetries
# building blocks of `switch_branch` and of the snake's switching, tested on their own
from jaxchain._bifurcation.branch_switching import (critical_directions,
                                                     switch_by_deflation,
                                                     symmetric_directions)

from helpers import internal, replace_internal

RING = jc.ChainParams(n_osc=2, v_d=1.5)
SHOOTING = jc.Shooting(root_finder="levenberg-marquardt", phase_oscillator=0)


@pytest.fixture(scope="module")
def branch_point():
    """The two-site state simulated from eq. (8), continued up in v_d to its first
    branch point."""
    # eq. (8) with one site excited reaches the two-site state at RING's v_d: no
    # retry at other speeds (which looks for one site there)
    found = internal("snake start orbits")(
        RING, (1,), options=jc.SimulationOptions(t_end=2000.0, transient=1500.0), retry=())
    orbit, _, reason = found[1]
    assert reason is None
    orbit = jc.periodic_orbit(RING, (orbit.y0, float(orbit.period)), SHOOTING)
    assert abs(float(orbit.amplitudes[0] - orbit.amplitudes[1])) < 1e-6  # symmetric
    problem = jc.cycle_problem(orbit, SHOOTING)
    branch = jc.continuation(problem, options=jc.ContinuationOptions(
        ds=0.02, ds_max=0.1, p_min=1.0, p_max=2.0, max_points=12))
    points = [b for b in jc.locate_bifurcations(problem, branch) if b.kind == "branch point"]
    assert points and abs(points[0].multiplier - 1) < 1e-4
    return problem, branch, points[0]


def _switched(problem, branch, point, step):
    new, tangent = jc.switch_branch(problem, branch, point, step=step)
    return new, jc.continuation(new, options=jc.ContinuationOptions(
        ds=step, ds_max=0.05, p_min=1.0, p_max=2.0, max_points=8), tangent=tangent)


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
        new, switched = _switched(problem, branch, point, step)
        assert residual(new) < 1e-6  # a solution, off the followed branch
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


def residual(problem) -> float:
    z = np.concatenate([np.asarray(problem.u0), [float(problem.value())]])
    return float(np.max(np.abs(np.asarray(problem(z)))))


def test_switching_needs_a_branch_point(branch_point):
    problem, branch, point = branch_point
    with pytest.raises(ValueError, match="step"):
        jc.switch_branch(problem, branch, point, step=0.0)
    fold = dataclasses.replace(point, kind="fold")
    with pytest.raises(ValueError, match="branch point"):
        jc.switch_branch(problem, branch, fold)


@pytest.mark.study
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
    found = jc.localized_branches(RING, (2,), **kwargs)
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
    again = jc.localized_branches(RING, (2,), **kwargs)  # read back, not recomputed
    assert list(again["datasets"]) == labels
    assert np.array_equal(again["datasets"]["k=2 switched 1"]["u"].values,
                          found["datasets"]["k=2 switched 1"]["u"].values)


@pytest.mark.study
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
    found = jc.localized_branches(RING, (2, 1), **kwargs)
    assert [b["label"] for b in found["summary"]["branches"]] == ["k=1"]
    (flagged,) = found["summary"]["not_periodic"]
    assert flagged["excited"] == 2 and "continuation failed" in flagged["reason"]

    def computes(*args, **kwargs):
        raise AssertionError("the stored starts are read back")

    replace_internal(monkeypatch, "snake starts", computes)
    again = jc.localized_branches(RING, (2, 1), **kwargs)
    assert again["summary"]["not_periodic"] == found["summary"]["not_periodic"]
    assert list(again["datasets"]) == ["k=1"]


@pytest.mark.study
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
    args = (SHOOTING, problem, branch, point, jc.ContinuationOptions(max_points=2),
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
    assert residual(new) < 1e-6 and float(tangent[-1]) < 0
    _, switched = _switched(problem, branch, point, 0.01)
    ok = np.asarray(switched.converged)
    u = np.asarray(switched.u)[ok][np.argmin(np.abs(np.asarray(switched.p)[ok] - p))]
    keller = jc.periodic_orbit(jc.with_parameter(RING, "v_d", p),
                               (u[:-1].reshape(2, -1), float(u[-1])), SHOOTING)
    deflated = jc.periodic_orbit(jc.with_parameter(RING, "v_d", p),
                                 (np.asarray(new.u0[:-1]).reshape(2, -1), float(new.u0[-1])),
                                 SHOOTING)
    assert abs(float(deflated.period - keller.period)) < 1e-7
    # amplitudes from 4096 samples a period (Shooting.n_samples): the sampled
    # extremes of one orbit started at another phase (the swapped copy starts at the
    # other oscillator's turning point) differ by up to |x''| dt^2 / 8, below 1e-6
    np.testing.assert_allclose(np.sort(np.asarray(deflated.amplitudes)),
                               np.sort(np.asarray(keller.amplitudes)), atol=2e-6)
    assert abs(float(keller.amplitudes[0] - keller.amplitudes[1])) > 1e-4


@pytest.mark.study
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
    found = internal("snake start orbits")(
        ring, (1,), method=jc.Shooting.from_simulations(jc.Exact()),
        options=jc.SimulationOptions(t_end=2000.0, transient=1500.0))
    orbit, sim, reason = found[1]
    assert reason is None
    shooting = jc.Shooting(jc.Exact().for_orbits(), phase_oscillator=sim["phase_oscillator"])
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
