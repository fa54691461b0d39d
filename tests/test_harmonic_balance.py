"""Harmonic balance (`HarmonicBalance`, the alternating frequency-time scheme)
against shooting on the same smoothed model, a second solver: the single
oscillator's stick-slip cycle at v_d 1.5 (eps 1e-2), its Floquet multipliers by
Hill's method and by one monodromy integration, and its branch from the fold down
to the Hopf point, whose v_d is known in closed form."""

import equinox as eqx
import jax
import numpy as np
import pytest

import jaxchain as jc

PARAMS = jc.ChainParams(n_osc=1, v_d=1.5)
EPS = 1e-2
SHOOTING = jc.Shooting(jc.Smoothed(eps=EPS).for_orbits())


@pytest.fixture(scope="module")
def shot():
    """The stick-slip cycle by shooting."""
    guess = (jc.Exact().steady_sliding(PARAMS) + 1.0, 6.3)
    return jc.periodic_orbit(PARAMS, guess, SHOOTING)


@pytest.mark.numerics
@pytest.mark.slow
@pytest.mark.study
def test_the_stick_slip_cycle_converges_to_shooting_s_as_harmonics_grow(shot):
    """From shooting's orbit as the guess: amplitude and period errors fall as H
    doubles (16, 32, 64: the velocity's kink at the stick phase makes the
    coefficients fall slowly), to below 1e-5 relative at H = 64, where the orbit
    sticks as shooting's does."""
    errors = []
    for h in (16, 32, 64):
        orbit = jc.periodic_orbit(PARAMS, shot, jc.HarmonicBalance(eps=EPS, harmonics=h))
        errors.append(max(abs(float(orbit.amplitudes[0] / shot.amplitudes[0]) - 1),
                          abs(float(orbit.period / shot.period) - 1)))
    assert errors[0] > errors[1] > errors[2] and errors[2] < 1e-5, errors
    assert int(orbit.n_halc) == int(shot.n_halc) == 1


@pytest.mark.numerics
@pytest.mark.parametrize("floquet", ["hill", "monodromy"])
def test_floquet_multipliers_agree_with_shooting_s(shot, floquet):
    """At H = 64 both ways of computing the multipliers give shooting's: the trivial
    one 1 to 1e-5 (the series' own error at H = 64, the test above: a trajectory
    integrated from its start leaves it by that much over a period) and the other
    (the stick phase loses the velocity perturbation) 0 to 1e-6; det M by
    Liouville's formula on the series within 5 % of shooting's (about 4e-12: the
    integral of the field's divergence, -26.3, to 0.05)."""
    orbit = jc.periodic_orbit(PARAMS, shot, jc.HarmonicBalance(eps=EPS, harmonics=64,
                                                               floquet=floquet))
    m = np.asarray(orbit.multipliers)
    assert abs(m[int(orbit.trivial)] - 1) < 1e-5
    assert np.max(np.abs(np.delete(m, int(orbit.trivial)))) < 1e-6
    assert np.max(np.abs(np.asarray(shot.multipliers)[1:])) < 1e-6
    assert abs(np.log(float(orbit.monodromy_determinant))
               - np.log(float(shot.monodromy_determinant))) < 0.05


@pytest.mark.study
@pytest.mark.numerics
@pytest.mark.slow
def test_the_branch_from_the_fold_to_the_hopf_point(shot):
    """`follow_branch` with harmonic balance, from the cycle at v_d 1.5 up through
    the fold and down to steady sliding: the fold where shooting's driver finds it
    (to 1e-6), the Hopf point where the eigenvalues of steady sliding cross (`hopf_vd`,
    no orbit involved; to 1e-6), the branch cut there as shooting's is."""
    options = jc.ContinuationOptions(ds=0.05, ds_max=0.2, p_min=1.0, p_max=3.0,
                                     max_points=200)
    hb = jc.HarmonicBalance(eps=EPS, harmonics=64)
    followed = {name: jc.follow_branch(shot, method, options)
                for name, method in (("hb", hb), ("shooting", SHOOTING))}
    folds = {name: [b.p for b in f.bifurcations if b.kind == "fold"]
             for name, f in followed.items()}
    assert len(folds["hb"]) == len(folds["shooting"]) == 1
    assert abs(folds["hb"][0] - folds["shooting"][0]) < 1e-6
    (hopf,) = [b.p for b in followed["hb"].bifurcations if b.kind == "Hopf"]
    assert abs(hopf - float(jc.hopf_vd(PARAMS, engine=jc.Smoothed(eps=EPS)))) < 1e-6
    assert followed["hb"].stops["high"] == followed["shooting"].stops["high"] == "hopf"


@pytest.mark.parametrize("fields, says", [
    ({"harmonics": 0}, "harmonics"), ({"harmonics": 8, "time_samples": 16}, "time_samples"),
    ({"floquet": "fourier"}, "floquet"), ({"eps": 0.0}, "eps"),
    ({"newton_tol": 0.0}, "newton_tol"), ({"phase_oscillator": -1}, "phase_oscillator")])
def test_bad_settings_are_refused_by_name(fields, says):
    with pytest.raises(jc.ValidationError, match=says):
        jc.HarmonicBalance(**fields)


def test_a_guess_of_the_wrong_shape_and_a_state_without_its_series_are_refused():
    """The unknowns are Fourier coefficients: a state and a period alone do not give
    them (`pack` refuses in one line), and a guess must have the chain's shape."""
    method = jc.HarmonicBalance(harmonics=4)
    with pytest.raises(jc.ValidationError, match="state and a period"):
        method.pack(np.zeros((2, 1)), 6.3)
    with pytest.raises(jc.ValidationError, match="shape"):
        jc.periodic_orbit(PARAMS, (np.zeros((2, 3)), 6.3), method)


@pytest.mark.numerics
@pytest.mark.study
def test_vmapped_over_mistuning_draws_equals_the_draws_one_at_a_time(shot):
    """Harmonic balance is a fixed-size Newton iteration: `jax.vmap` of its solve
    over 6 stiffness-mistuning draws (sigma 0.02, `mistune`, stacked by
    `stack_chains`) gives each draw's orbit as solving it alone does, to Newton's
    tolerance (two compiled programs: 1e-8 relative to each unknown); every draw
    converges and the draws differ from each other by far more."""
    method = jc.HarmonicBalance(eps=EPS, harmonics=32)
    u0 = method.start(shot)
    batch = jc.stack_chains([jc.mistune(PARAMS, 0.02, seed) for seed in range(6)])
    together, ok = jax.vmap(lambda p: method.solve(p, u0))(batch)
    assert np.all(np.asarray(ok))
    # each lane of the same batch alone: one compiled solve for all six
    lanes = [jax.tree.map(lambda a, i=i: a[i], batch) for i in range(6)]
    alone = np.stack([np.asarray(method.solve(p, u0)[0]) for p in lanes])
    np.testing.assert_allclose(np.asarray(together), alone, rtol=1e-8, atol=1e-8)
    assert np.ptp(alone[:, -1]) > 1e-4  # the periods of the draws differ


@pytest.mark.numerics
@pytest.mark.study
def test_the_amplitude_s_derivative_in_eps_against_central_differences(shot):
    """d A / d eps of the stick-slip cycle at eps 1e-2 (H = 32) by optimistix's
    implicit differentiation through Newton's method, in reverse mode (`jax.grad`)
    and forward mode (`jax.jvp`), against central differences of the solved
    amplitude (step 1e-5, error O(h^2) ~ 1e-7 relative)."""
    u0 = jc.HarmonicBalance(eps=EPS, harmonics=32).start(shot)

    @jax.jit
    def amplitude(eps):
        method = jc.HarmonicBalance(eps=eps, harmonics=32)
        u, _ = method.solve(PARAMS, u0)
        return method.describe(u, PARAMS).amplitudes[0]

    reverse = float(jax.grad(amplitude)(EPS))
    forward = float(jax.jvp(amplitude, (EPS,), (1.0,))[1])
    h = 1e-5
    central = float((amplitude(EPS + h) - amplitude(EPS - h)) / (2 * h))
    assert abs(reverse - central) < 1e-6 * abs(central)
    assert abs(forward - central) < 1e-6 * abs(central)


@pytest.fixture(scope="module")
def damped_ring():
    """A mistuned ring of four friction dampers (Coulomb, mu 0.3, v_d 0, eta_c 0.1)
    under an engine-order-1 wave near resonance, solved from rest by harmonic
    balance (H = 16, 128 samples, eps 1e-3) with each linear solver."""
    forcing = jc.Forcing.engine_order(4, 1, 1.0, 1.05)
    params = jc.mistune(jc.ChainParams(n_osc=4, eta_c=0.1, v_d=0.0, friction=jc.Coulomb(0.3),
                                       forcing=forcing), 0.05, 1)
    methods = {name: jc.HarmonicBalance(eps=1e-3, harmonics=16, linear_solver=name)
               for name in ("blocks", "ring", "lu")}
    return params, methods


@pytest.mark.numerics
@pytest.mark.slow
@pytest.mark.study
def test_the_oscillator_blocks_solve_the_coupled_ring_as_lu_does(damped_ring):
    """GMRES preconditioned by the Jacobian's oscillator blocks (the friction force
    couples one oscillator's harmonics only; the coupling springs couple the
    oscillators), and the block elimination over the ring's oscillators, each
    reach the orbit that LU of the whole Jacobian reaches, to
    Newton's tolerance (1e-9, two programs), from rest; and the derivative of the
    largest amplitude in mu, through its transposed solve (reverse mode) and forward
    mode, is that of central differences to 1e-6. The amplitude is the largest of 4096 samples, piecewise
    smooth in mu, so central differences err as O(h) (measured: 2.4e-6 relative at
    h = 1e-5, 2e-8 at 1e-6, rounding 1e-9): the step is 1e-6."""
    params, methods = damped_ring
    u0 = methods["lu"].unknowns(params, np.zeros((2, 4)), 1.0)
    solved = {name: m.solve(params, u0) for name, m in methods.items()}
    assert all(bool(ok) for _, ok in solved.values())
    for name in ("blocks", "ring"):
        np.testing.assert_allclose(solved[name][0], solved["lu"][0], rtol=1e-9, atol=1e-9)
    method = methods["blocks"]

    @jax.jit
    def largest(mu):
        p = jc.with_parameter(params, "mu", mu)
        u, _ = method.solve(p, solved["lu"][0])
        return jax.numpy.max(method.describe(u, p).amplitudes)

    h = 1e-6
    central = float((largest(0.3 + h) - largest(0.3 - h)) / (2 * h))
    assert abs(float(jax.grad(largest)(0.3)) - central) < 1e-6 * abs(central)
    assert abs(float(jax.jvp(largest, (0.3,), (1.0,))[1]) - central) < 1e-6 * abs(central)


@pytest.mark.numerics
@pytest.mark.parametrize("params", [
    jc.ChainParams(n_osc=5, xi=1e-3, v_d=0.0, friction=jc.Coulomb(mu=0.003),
                   forcing=jc.Forcing.engine_order(5, 2, 0.01, 1.0)),
    jc.ChainParams(n_osc=4, v_d=1.5, mass=[1.0, 2.0, 1.5, 1.0], stiffness=[1.0, 1.1, 0.9, 1.0]),
    jc.ChainParams(n_osc=1, v_d=1.5)], ids=["forced ring", "masses", "one oscillator"])
def test_the_assembled_jacobian_is_the_residual_s_derivative(params):
    """`HarmonicBalance.jacobian` (assembled from the field's linear part and the
    friction's slope at the samples) equals forward-mode differentiation of the
    residual through its FFTs, at a random point, to rounding; the residual that LU
    differentiates by it has that derivative in u and its own in eps."""
    hb = jc.HarmonicBalance(eps=1e-2, harmonics=4, linear_solver="lu")
    u = jax.numpy.asarray(np.random.default_rng(1).standard_normal(
        params.n_osc * 9 + 1)).at[-1].set(6.0)
    # each compiled (eqx.filter_jit): differentiated op by op they take a minute
    reference = eqx.filter_jit(jax.jacfwd(hb._balance))(u, params)
    scale = np.max(np.abs(reference))
    assert np.max(np.abs(eqx.filter_jit(hb.jacobian)(u, params) - reference)) < 1e-12 * scale
    assert np.max(np.abs(eqx.filter_jit(jax.jacrev(hb.residual))(u, params)
                         - reference)) < 1e-12 * scale

    def in_eps(method):
        return eqx.filter_jit(jax.jacfwd(lambda e: getattr(jc.HarmonicBalance(
            eps=e, harmonics=4, linear_solver="lu"), method)(u, params)))
    assert np.allclose(in_eps("residual")(1e-2), in_eps("_balance")(1e-2),
                       rtol=1e-12, atol=1e-12 * scale)


@pytest.mark.parametrize("n_osc, boundary", [(7, "ring"), (5, "free"), (2, "ring")])
@pytest.mark.study
def test_the_block_elimination_over_a_ring_solves_as_lu(n_osc, boundary):
    """Harmonic balance with the block elimination over the oscillators
    (`linear_solver="ring"`) takes Newton's steps exactly: from LU's orbit (a
    forced, mistuned ring or line of friction dampers, H = 3) moved by 1e-3, four
    steps reach LU's orbit to Newton's tolerance (1e-9, two programs), as
    quadratic convergence does (1e-3, 1e-6, 1e-12); a solve wrong by a fixed
    fraction would converge linearly, and fail within four."""
    forcing = jc.Forcing.engine_order(n_osc, 1, 1.0, 1.05)
    params = jc.mistune(jc.ChainParams(n_osc=n_osc, eta_c=0.1, v_d=0.0, boundary=boundary,
                                       friction=jc.Coulomb(0.3), forcing=forcing), 0.05, 2)
    lu = jc.HarmonicBalance(eps=1e-2, harmonics=3, linear_solver="lu")
    u, ok = lu.solve(params, lu.unknowns(params, np.zeros((2, n_osc)), 1.0))
    assert bool(ok)
    moved = np.asarray(u) * (1 + 1e-3 * np.random.default_rng(5).standard_normal(u.shape))
    ring = jc.HarmonicBalance(eps=1e-2, harmonics=3, linear_solver="ring", newton_steps=4)
    u_ring, ok = ring.solve(params, moved)
    assert bool(ok)
    np.testing.assert_allclose(u_ring, u, rtol=1e-9, atol=1e-9)
    if boundary != "ring" or n_osc < 3:
        return

    # its derivatives solve by LU (`damped_newton`'s adjoint_solver): forward and
    # reverse mode of the coefficients' norm in mu against central differences
    # (smooth in mu; Newton's last step leaves an error far below its tolerance)
    @jax.jit
    def norm(mu):
        p = jc.with_parameter(params, "mu", mu)
        return jax.numpy.sum(ring.solve(p, u)[0][:-1] ** 2)

    h = 1e-6
    central = float((norm(0.3 + h) - norm(0.3 - h)) / (2 * h))
    assert abs(float(jax.grad(norm)(0.3)) - central) < 1e-6 * abs(central)
    assert abs(float(jax.jvp(norm, (0.3,), (1.0,))[1]) - central) < 1e-6 * abs(central)


def test_the_ring_elimination_refuses_a_lattice():
    params = jc.ChainParams(graph=jc.Graph.lattice(3, 3), v_d=1.5)
    method = jc.HarmonicBalance(eps=1e-2, harmonics=2, linear_solver="ring")
    with pytest.raises(jc.ValidationError, match="linear_solver 'ring'"):
        method.solve(params, method.unknowns(params, np.ones((2, 9)), 6.3))
