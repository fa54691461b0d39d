"""Any chain, any friction law: mistuned oscillators, open ends and friction laws as
objects, each checked against something independent of jaxchain (closed-form
modes, numpy.linalg.eigh, scipy's event-driven stick-slip cycle, brentq, an energy
balance integrated beside the motion)."""

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.optimize import brentq

import jaxchain as jc
from helpers import TIGHT, assert_usage_error, assert_within_drift, scipy_stick_slip_cycle, \
    stribeck_mu

STRIBECK = dict(mu_s=1.0, mu_c=0.5, v_s=0.5, delta=2.0, viscous=0.05)


def _dense_stiffness(stiffness, eta, boundary):
    """K of x'' = -K x, assembled spring by spring in NumPy (independent of
    jaxchain's coupling_force): ground springs k_n, coupling springs eta_l."""
    n = len(stiffness)
    k = np.diag(np.asarray(stiffness, dtype=float))
    pairs = {"ring": [(i, (i + 1) % n) for i in range(n)],
             "free": [(i, i + 1) for i in range(n - 1)],
             "fixed": [(None, 0)] + [(i, i + 1) for i in range(n - 1)] + [(n - 1, None)]}
    for e, (a, b) in zip(np.broadcast_to(eta, (len(pairs[boundary]),)), pairs[boundary]):
        for i, j in ((a, b), (b, a)):
            if i is not None:
                k[i, i] += e
                if j is not None:
                    k[i, j] -= e
    return k


@pytest.mark.numerics
@pytest.mark.parametrize("boundary", ["free", "fixed"])
def test_linear_modes_of_open_chains_are_the_closed_form(boundary):
    """Homogeneous open chains: omega_k^2 = 1 + 4 eta sin^2(theta_k / 2) with theta_k
    = k pi / N (free, k = 0..N-1, modes cos(theta_k (n + 1/2))) and k pi / (N + 1)
    (fixed, k = 1..N, modes sin(theta_k n)), from the stiffness matrix and from the
    undamped Jacobian at steady sliding (Coulomb friction, flat: pure +-i omega)."""
    n, eta = 7, 0.3
    params = jc.ChainParams(n_osc=n, eta_c=eta, xi=0.0, boundary=boundary,
                            friction=jc.Coulomb(0.5))
    if boundary == "free":
        theta = np.arange(n) * np.pi / n
        shapes = np.cos(np.outer(np.arange(n) + 0.5, theta))
    else:
        theta = np.arange(1, n + 1) * np.pi / (n + 1)
        shapes = np.sin(np.outer(np.arange(1, n + 1), theta))
    omega2 = 1 + 4 * eta * np.sin(theta / 2) ** 2
    values, vectors = np.linalg.eigh(np.asarray(jc.stiffness_matrix(params)))
    order = np.argsort(omega2)
    assert np.allclose(values, omega2[order], atol=1e-13)
    shapes = shapes[:, order] / np.linalg.norm(shapes[:, order], axis=0)
    assert np.allclose(np.abs(np.sum(shapes * vectors, axis=0)), 1.0, atol=1e-10)
    eig = np.asarray(jc.steady_sliding_eigenvalues(params))
    assert np.max(np.abs(eig.real)) < 1e-12
    assert np.allclose(np.sort(eig.imag[eig.imag > 0]), np.sqrt(np.sort(omega2)), atol=1e-12)


@pytest.mark.numerics
@pytest.mark.parametrize("boundary", ["ring", "free", "fixed"])
def test_a_mistuned_chain_has_the_modes_of_its_dense_stiffness_matrix(boundary):
    """A mistuned chain with one eta per link: jaxchain's stiffness matrix (from the
    one coupling function) equals the matrix assembled spring by spring, and the
    frequencies of the undamped Jacobian are those of numpy.linalg.eigh."""
    n = 6
    links = {"ring": n, "free": n - 1, "fixed": n + 1}[boundary]
    params = jc.mistune(jc.ChainParams(n_osc=n, xi=0.0, boundary=boundary,
                                       eta_c=np.linspace(0.01, 0.05, links),
                                       friction=jc.Coulomb(0.5)), 0.02, 4)
    dense = _dense_stiffness(params.stiffness, params.eta_c, boundary)
    assert np.allclose(jc.stiffness_matrix(params), dense, rtol=0, atol=1e-15)
    omega = np.sqrt(np.linalg.eigvalsh(dense))
    eig = np.asarray(jc.steady_sliding_eigenvalues(params))
    assert np.allclose(np.sort(eig.imag[eig.imag > 0]), omega, atol=1e-12)


def test_mistuning_is_recorded_and_rebuilds_the_same_chain():
    p = jc.mistune(jc.ChainParams(n_osc=5, boundary="free"), 0.01, 7)
    draws = np.asarray(jax.random.normal(jax.random.key(7), (5,), dtype=float))
    assert np.array_equal(p.stiffness, 1 + 0.01 * draws)
    assert p.mistuning == jc.Mistuning(sigma=0.01, seed=7)
    assert jc.chain_from_record(jc.chain_record(p)) == p
    with pytest.raises(ValueError, match="mistuning record"):
        jc.with_parameter(p, "stiffness", np.ones(5))


def test_no_mistuning_gives_bitwise_the_homogeneous_ring():
    """sigma = 0 keeps the paper's ring, bit for bit (the same compiled run), on a
    stick-slipping ring of 2."""
    y0 = jc.OutOfPhaseExcitation.eq8([True, False])
    base = jc.ChainParams(n_osc=2)
    a = jc.simulate(base, y0, options=TIGHT)
    b = jc.simulate(jc.mistune(base, 0.0, 3), y0, options=TIGHT)
    assert int(a.n_halc) >= 1
    assert np.array_equal(a.amplitudes, b.amplitudes) and a.num_steps == b.num_steps
    assert np.array_equal(a.y_final, b.y_final)


@pytest.mark.numerics
def test_the_fourier_route_and_the_jacobian_agree_on_the_ring():
    """On the homogeneous ring the block-circulant (Fourier) eigenvalues are those of
    the dense Jacobian by numpy.linalg.eigvals."""
    params = jc.ChainParams(n_osc=9, v_d=1.0, eta_c=0.2)
    def ordered(values):  # equal real parts up to rounding: order by frequency
        values = np.asarray(values)
        return values[np.lexsort((values.real.round(8), values.imag))]

    fourier = ordered(jc.steady_sliding_eigenvalues(params))
    dense = ordered(np.linalg.eigvals(np.asarray(jc.Smoothed().jacobian(params))))
    assert np.allclose(fourier, dense, atol=1e-10)


@pytest.mark.numerics
def test_hopf_point_of_a_stribeck_chain_is_the_root_of_its_effective_damping():
    """A mistuned open chain with a Stribeck law (uniform xi and load): every mode
    loses stability where 2 xi + mu'(v_d) = 0, found here by brentq on the
    derivative of the law written in the test."""
    xi = 0.05
    law = jc.Stribeck(**STRIBECK)
    params = jc.mistune(jc.ChainParams(n_osc=5, xi=xi, boundary="free", friction=law,
                                       eta_c=0.02), 0.01, 2)

    def damping(v):
        s = (STRIBECK["mu_s"] - STRIBECK["mu_c"]) * np.exp(-(v / STRIBECK["v_s"]) ** 2)
        return 2 * xi - 2 * v / STRIBECK["v_s"] ** 2 * s + STRIBECK["viscous"]

    expected = brentq(damping, 0.5, 2.0, xtol=1e-14)
    hopf = jc.hopf_point(params, 1.0)
    assert abs(float(hopf.v_d[0]) - expected) < 1e-9
    assert abs(float(hopf.residual[0])) < 1e-10 and float(hopf.slope[0]) < 0


@pytest.mark.numerics
def test_hopf_point_of_a_mistuned_open_chain_with_eq1_is_the_closed_form():
    """With eq. (1) and uniform damping the Jacobian route gives the closed form of
    hopf_vd_analytic (the eps correction is 1e-1000 at eps = 1e-3)."""
    params = jc.mistune(jc.ChainParams(n_osc=6, boundary="fixed"), 0.02, 5)
    closed = float(jc.hopf_vd_analytic(jc.ChainParams()))
    assert abs(float(jc.hopf_vd(params)) - closed) < 1e-10
    with pytest.raises(ValueError, match="ExponentialDecay"):
        jc.hopf_vd_analytic(jc.ChainParams(friction=jc.Stribeck()))


@pytest.mark.numerics
@pytest.mark.study
def test_stribeck_stick_slip_cycle_against_the_exact_switch_model():
    """One oscillator with a Stribeck law at v_d = 1: the smoothed model (eps = 1e-3)
    and the non-smooth reference against scipy's event-driven cycle (the slip arc
    integrated to its return to the belt, then stick)."""
    params = jc.ChainParams(n_osc=1, v_d=1.0, friction=jc.Stribeck(**STRIBECK))
    amplitude, period = scipy_stick_slip_cycle(params, mu=stribeck_mu(**STRIBECK))
    y0 = jc.OutOfPhaseExcitation.eq8([True])
    # the smoothed run's extrema and peak times in one run (one compiled program)
    obs = jc.observe(params, y0, [jc.Extrema(), jc.PeakTimes()],
                     options=jc.SimulationOptions(t_end=400.0, transient=300.0))
    assert int(obs["n_halc"]) == 1
    assert abs(float(obs["amplitudes"][0]) / amplitude - 1) < 5e-3
    ref = jc.simulate(params, y0,
                      engine=jc.Exact(jc.NonsmoothOptions.reference(t_end=400.0, transient=300.0)))
    assert abs(float(ref.amplitudes[0]) / amplitude - 1) < 1e-6
    times = np.asarray(obs["peak_times"])[0]
    measured = np.median(np.diff(times[np.isfinite(times)]))
    assert abs(measured / period - 1) < 5e-3


@pytest.mark.numerics
def test_energy_balance_of_a_mistuned_open_chain():
    """Along eq. (5) of a mistuned free chain with per-oscillator damping and loads,
    the mechanical energy changes by the friction work minus the viscous
    dissipation, both integrated beside the motion (Dopri8, rtol 1e-11). The
    friction force is written here (the Stribeck curve of `stribeck_mu` in
    jax.numpy, smoothed as -P_n mu tanh(v_rel/eps)), so that the balance checks the
    whole field, its elastic and its friction part."""
    n = 5
    params = jc.mistune(jc.ChainParams(n_osc=n, boundary="free", eta_c=np.full(n - 1, 0.3),
                                       xi=np.linspace(0.03, 0.07, n),
                                       load=np.linspace(0.8, 1.2, n),
                                       friction=jc.Stribeck(**STRIBECK)), 0.05, 1)
    eps = 0.05
    mu_s, mu_c, v_s, delta, viscous = (STRIBECK[k] for k in ("mu_s", "mu_c", "v_s", "delta",
                                                             "viscous"))

    def field(t, z, args):
        y, _ = z
        dy = jc.Smoothed(eps=eps).field(params, y)
        v = y[1]
        v_rel = v - params.v_d
        s = jnp.abs(v_rel)
        mu = mu_c + (mu_s - mu_c) * jnp.exp(-(s / v_s) ** delta) + viscous * s
        friction = -params.load * mu * jnp.tanh(v_rel / eps)
        return dy, jnp.stack([jnp.sum(friction * v), jnp.sum(2 * params.xi * v**2)])

    y0 = jnp.stack([jnp.linspace(-1.0, 2.0, n), jnp.zeros(n)])
    sol = diffrax.diffeqsolve(diffrax.ODETerm(field), diffrax.Dopri8(), 0.0, 60.0, 0.01,
                              (y0, jnp.zeros(2)),
                              stepsize_controller=diffrax.PIDController(rtol=1e-11, atol=1e-11),
                              max_steps=200_000)
    y1, (work, dissipated) = sol.ys[0][-1], sol.ys[1][-1]
    change = jc.mechanical_energy(params, y1) - jc.mechanical_energy(params, y0)
    assert abs(float(dissipated)) > 0.1  # it moved
    assert abs(float(change - (work - dissipated))) < 1e-8


@pytest.mark.numerics
@pytest.mark.study
def test_per_oscillator_arrays_are_never_read_as_lanes():
    """A chain whose per-oscillator length equals the lane count keeps its arrays per
    oscillator: lane_params adds the lane axis in front, and each lane of a batch of
    mistuning draws (stack_chains) equals its own run, to the integration tolerance
    of two compiled programs (`drift_bound`, at `TIGHT`)."""
    chains = [jc.mistune(jc.ChainParams(n_osc=3, boundary="free"), 0.05, s) for s in range(3)]
    lanes = jc.lane_params(chains[0], 3, v_d=np.array([1.3, 1.5, 1.7]))
    assert lanes.stiffness.shape == (3, 3) and lanes.v_d.shape == (3,)
    assert np.array_equal(lanes.stiffness[1], chains[0].stiffness)
    with pytest.raises(ValueError, match="ChainParams.v_d must have shape"):
        jc.with_parameter(chains[0], "v_d", np.array([1.3, 1.5, 1.7]))
    y0 = np.stack([np.asarray(jc.OutOfPhaseExcitation.eq8([False, True, False])(c))
                   for c in chains])
    batch = jc.run_lanes(jc.stack_chains(chains), y0, jc.SOLVERS["ros34pw2"](), TIGHT)
    assert np.all(batch.n_halc >= 1)  # the excited oscillator sticks
    for i, c in enumerate(chains):
        one = jc.simulate(c, y0[i], options=TIGHT)
        assert int(batch.n_halc[i]) == int(one.n_halc)
        steps = max(int(batch.num_steps[i]), int(one.num_steps))
        for field in ("amplitudes", "y_final"):
            assert_within_drift(getattr(batch, field)[i], getattr(one, field), TIGHT, steps,
                                field)


@pytest.mark.parametrize("make, says", [
    (lambda: jc.ChainParams(n_osc=5, stiffness=np.ones(3)), "ChainParams.stiffness"),
    (lambda: jc.ChainParams(n_osc=5, boundary="free", eta_c=np.ones(5)), "ChainParams.eta_c"),
    (lambda: jc.ChainParams(n_osc=5, load=-1.0), "ChainParams.load"),
    (lambda: jc.ChainParams(n_osc=5, boundary="open"), "ChainParams.boundary"),
    (lambda: jc.ChainParams(friction=jc.Stribeck(mu_c=-0.1)), "Stribeck.mu_c"),
    (lambda: jc.ChainParams(friction=jc.Stribeck(mu_s=0.2)), "Stribeck.mu_s"),
    (lambda: jc.ChainParams(n_osc=4, friction=jc.Stribeck(v_s=np.ones(3))), "Stribeck.v_s"),
    (lambda: jc.Polynomial(c1=-2.0), "Polynomial coefficients"),
    (lambda: jc.Coulomb(-0.1), "Coulomb.mu"),
    (lambda: jc.ChainParams(v_d=0.0), "ChainParams.v_d"),
    (lambda: jc.ChainParams(n_osc=3, forcing=jc.Forcing(1.0, 1.0, phase=np.ones(2))),
     "Forcing.phase"),
    (lambda: jc.Forcing(amplitude=-1.0, frequency=1.0), "Forcing.amplitude"),
    (lambda: jc.Forcing(amplitude=1.0, frequency=0.0), "Forcing.frequency"),
    (lambda: jc.ChainParams(friction=jc.Coulomb(), mu_st=2.0), "not both"),
    (lambda: jc.mistune(jc.ChainParams(), -0.1, 0), "Mistuning.sigma"),
])
def test_bad_chains_raise_naming_the_field(make, says):
    with pytest.raises(ValueError, match=says):
        make()


@pytest.mark.parametrize("argv, says", [
    (["localized", "--boundary", "open"], "--boundary"),
    (["sweep", "--friction", "stick:mu=1"], "--friction: unknown law 'stick'"),
    (["localized", "--friction", "stribeck:mu_c=-1"], "Stribeck.mu_c"),
    (["basin", "--friction", "stribeck:mu=1"], "--friction: stribeck takes"),
    (["boundaries", "--mistuning", "-1"], "--mistuning"),
    (["localized", "--chain", "/nonexistent/chain.toml"], "--chain"),
])
def test_bad_chain_options_exit_2_in_one_line(argv, says, capsys, tmp_path):
    assert_usage_error(argv + ["--out", str(tmp_path)], says, capsys)


def test_a_chain_file_gives_per_oscillator_arrays(tmp_path):
    path = tmp_path / "chain.toml"
    path.write_text('n_osc = 3\nboundary = "fixed"\neta_c = [0.01, 0.02, 0.03, 0.04]\n'
                    'load = [1.0, 0.9, 1.1]\nfriction = "polynomial"\nc1 = -0.4\n')
    p = jc.chain_from_file(path)
    assert p.boundary == "fixed" and np.array_equal(p.eta_c, [0.01, 0.02, 0.03, 0.04])
    assert isinstance(p.friction, jc.Polynomial) and float(p.friction.c1) == -0.4
    path.write_text("n_osc = 3\nstiffness = [1.0, 1.0]\n")
    with pytest.raises(ValueError, match="ChainParams.stiffness"):
        jc.chain_from_file(path)
