"""Identification against the event-driven non-smooth reference: records made by the
exact switch model (a different code path from the smoothed fit) with known
parameters, refitted; the Jacobian of a fit's residual through the engines' flow
against finite differences; the choice between friction laws; the names a fit
refuses."""

import contextlib
import json
import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxchain as jc

#: The rig of the tests: eq. (1) with parameters away from the defaults (which are
#: the fit's starting values where the records say nothing), one oscillator.
TRUE = {"mu_st": 1.1, "mu_d": 0.6, "v0": 0.35, "xi": 0.04}
SPEEDS = (0.4, 0.7, 1.0)
RIG = jc.ChainParams(n_osc=1, xi=TRUE["xi"], friction=jc.ExponentialDecay(
    mu_st=TRUE["mu_st"], mu_d=TRUE["mu_d"], v0=TRUE["v0"]))
#: Short records, for a cheap fit: 20 time units (about three stick-slip cycles)
#: sampled every 0.2, two windows each.
T_END, DT = 20.0, 0.2


@pytest.fixture(scope="module")
def clean_records():
    jc.configure()
    return [jc.reference_record(RIG, v_d, T_END, DT) for v_d in SPEEDS]


def _noisy(records, rng, noise=0.005, offsets=(0.0, 0.0, 0.0)):
    out = []
    for rec, offset in zip(records, offsets):
        amplitude = 0.5 * (rec.x.max(axis=0) - rec.x.min(axis=0))
        x = rec.x + noise * amplitude * rng.standard_normal(rec.x.shape) + offset
        out.append(jc.Record(t=rec.t, x=x, oscillators=rec.oscillators, v=None,
                             v_d=rec.v_d, source=rec.source))
    return out


def _fit(records, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return jc.identify(records, jc.ChainParams(n_osc=1), offsets=True, **kw)


@pytest.mark.numerics
def test_the_reference_trajectory_is_the_reference_run():
    """Sampled event by event, the records' state at t_end (`reference_record`, with
    its velocities) is that of `simulate` on the exact engine (another program,
    both at rtol 1e-12: agreement to 1e-8), and in stick the oscillator moves with
    the belt exactly. The samples of the records (`T_END`, `DT`), so that the
    sampled run is the records' program. A record of no sample interval is
    refused."""
    jc.configure()
    params = jc.with_parameter(RIG, "v_d", 0.7)
    rec = jc.reference_record(RIG, 0.7, T_END, DT, velocities=True)
    np.testing.assert_allclose(rec.t, np.arange(int(round(T_END / DT)) + 1) * DT)
    run = jc.simulate(params, np.zeros((2, 1)), engine=jc.Exact(jc.NonsmoothOptions.reference(
        t_end=T_END, transient=T_END / 2, chunk_length=5.0)))
    np.testing.assert_allclose([rec.x[-1], rec.v[-1]], np.asarray(run.y_final), atol=1e-8)
    sticking = np.abs(rec.v[:, 0] - 0.7) < 1e-12
    assert 0.1 < sticking.mean() < 0.9  # stick-slip, with stick phases
    for dt in (-DT, 0.0, 2 * T_END):
        with pytest.raises(jc.ValidationError, match="dt and t_end"):
            jc.reference_record(RIG, 0.7, T_END, dt)


def test_bad_fit_names_are_refused(clean_records):
    """`identify` refuses a name it cannot fit before it integrates anything."""
    for fit, says in [(("v_d",), "cannot be fitted"), (("eps",), "cannot be fitted"),
                      (("mu_s",), "unknown parameter"), (("xi", "xi"), "twice")]:
        with pytest.raises(jc.ValidationError, match=says):
            jc.identify(clean_records, jc.ChainParams(n_osc=1), fit)


#: The engines of the Jacobian's test, at tight tolerances (rtol 1e-10, atol 1e-12; the
#: fit's eps, 1e-5, and its step budget per window, `SimulationOptions().max_steps`).
TIGHT = {"smoothed": jc.Smoothed(options=jc.SimulationOptions(rtol=1e-10, atol=1e-12),
                                 eps=1e-5),
         "exact": jc.Exact(jc.NonsmoothOptions(rtol=1e-10, atol=1e-12,
                                               max_steps=jc.SimulationOptions().max_steps))}


def _law(theta):
    """The chain of `RIG` at belt speed 0.7 from the unknowns theta of a fit, in the
    parametrisation `identify` documents: mu_d = exp(theta_1), mu_st = mu_d +
    exp(theta_0), v0 = exp(theta_2), xi = exp(theta_3) (written here, not taken from
    jaxchain)."""
    mu_d = jnp.exp(theta[1])
    params = jc.with_parameter(RIG, "v_d", 0.7)
    for name, value in [("mu_d", mu_d), ("mu_st", mu_d + jnp.exp(theta[0])),
                        ("v0", jnp.exp(theta[2])), ("xi", jnp.exp(theta[3]))]:
        params = jc.with_parameter(params, name, value)
    return params


@pytest.mark.numerics
@pytest.mark.parametrize("engine", ["smoothed", "exact"])
@pytest.mark.study
def test_the_jacobian_of_the_misfit_is_that_of_finite_differences(engine):
    """Forward-mode through the integration (`AbstractEngine.flow`, what a fit
    integrates in each window) against central differences of the same residual:
    a fit's, written here from the engine's public flow, on one record (belt speed
    0.7, `T_END`, `DT`) cut as `identify` cuts it into two windows of 10, its
    unknowns the four parameters in the fit's parametrisation (`_law`) and the two
    windows' initial states; the residual the displacements at the samples and
    three times the jump between the windows. At tight tolerances (rtol 1e-10,
    atol 1e-12): the differences' truncation (h^2) and the integration's noise
    (atol / h) are both below 1e-5 with h = 1e-4, so they agree to 1e-4 of the
    Jacobian's largest entry, and an error in a single entry would show. The
    smoothed model through diffrax; the exact switch model through its events
    (each event time by the implicit function theorem: the saltation of every stick
    and slip switch of the windows' stick phases), where a switch missed by the
    derivative would be off by the jump of the vector field there, of order one."""
    jc.configure()
    engine = TIGHT[engine]
    rec = jc.reference_record(RIG, 0.7, T_END, DT, velocities=True)
    first, second = np.array_split(np.arange(rec.t.size), 2)  # identify's two windows
    # each window's samples from its start and the next window's start; the second,
    # one sample shorter, padded with its last time (one program for both windows)
    times = jnp.asarray([np.append(rec.t[first], rec.t[second[0]]),
                         np.append(rec.t[second], [rec.t[-1]] * 2) - rec.t[second[0]]])
    truth = np.log([TRUE["mu_st"] - TRUE["mu_d"], TRUE["mu_d"], TRUE["v0"], TRUE["xi"]])
    states = [[rec.x[w[0], 0], rec.v[w[0], 0]] for w in (first, second)]

    @jax.jit
    def residual(u):
        ys = jax.vmap(engine.flow, in_axes=(None, 0, 0))(
            _law(u[:4]), jnp.reshape(u[4:], (2, 2, 1)), times)
        jump = ys[0, -1, :, 0] - u[6:8]
        return jnp.concatenate([ys[0, :-1, 0, 0], ys[1, :second.size, 0, 0], 3.0 * jump])

    u0 = jnp.asarray(np.concatenate([truth, np.ravel(states)]))
    u = u0 + 0.01 * jnp.sin(jnp.arange(u0.size))  # off the data, every entry in play
    exact = np.asarray(jax.jacfwd(residual)(u))
    h = 1e-4
    columns = [(residual(u + h * e) - residual(u - h * e)) / (2 * h)
               for e in np.eye(u.size)]
    approx = np.stack([np.asarray(c) for c in columns], axis=1)
    assert exact.shape == (rec.t.size + 2, 8) and np.all(np.isfinite(exact))
    assert np.abs(exact).max() > 1.0
    np.testing.assert_allclose(exact, approx, rtol=0, atol=1e-4 * np.abs(exact).max())


@contextlib.contextmanager
def _traces():
    """The programs JAX traces inside the block (a list, filled as they are traced):
    a jitted function called again with arrays of the same shapes traces nothing."""
    traced = []

    def listen(event, duration, **kwargs):
        if event == "/jax/core/compile/jaxpr_trace_duration":
            traced.append(event)

    jax.monitoring.register_event_duration_secs_listener(listen)
    try:
        yield traced
    finally:
        jax.monitoring.unregister_event_duration_listener(listen)


@pytest.mark.numerics
def test_a_windows_states_are_differentiable_in_the_engines_eps():
    """What a fit integrates in a window (`Smoothed.flow`, eps an array leaf of
    the engine): its forward-mode derivative with respect to eps against central
    differences of the same states, on one oscillator from rest through its stick
    and slip phases at rtol 1e-10, atol 1e-12 (the largest derivative is about 9;
    the differences' truncation and the integration's noise, atol / h, are about
    3e-6 with h = 1e-6, so they agree to 1e-5 of the largest, and a derivative that
    missed eps would be 0). The two differenced runs, at eps 1e-3 +- h, are one
    compiled program: a new eps traces nothing."""
    jc.configure()
    params = jc.with_parameter(RIG, "v_d", 0.7)
    y0, times = jnp.zeros((2, 1)), jnp.linspace(0.0, 10.0, 51)
    engine = jc.Smoothed(options=jc.SimulationOptions(rtol=1e-10, atol=1e-12), eps=1e-3)

    @eqx.filter_jit
    def states(engine):
        ys = engine.flow(params, y0, times)
        return ys, jnp.all(jnp.isfinite(ys))

    exact = np.asarray(jax.jit(jax.jacfwd(
        lambda eps: states(engine.with_parameter("eps", eps))[0]))(jnp.asarray(1e-3)))
    h = 1e-6
    up, ok = states(engine.with_parameter("eps", np.asarray(1e-3 + h)))
    with _traces() as traced:
        down, ok_down = states(engine.with_parameter("eps", np.asarray(1e-3 - h)))
    assert bool(ok) and bool(ok_down) and traced == []
    approx = (np.asarray(up) - np.asarray(down)) / (2 * h)
    assert np.abs(exact).max() > 1.0
    np.testing.assert_allclose(exact, approx, rtol=0, atol=1e-5 * np.abs(exact).max())


@pytest.mark.numerics
@pytest.mark.study
def test_a_fit_at_another_eps_runs_the_compiled_program_of_the_first(clean_records):
    """The fit's eps is the engine's array leaf (`IdentifyOptions.engine`), not a
    static setting: a second fit at another eps traces nothing (it runs the first
    fit's compiled program), and its xi carries the smoothing's bias at its own eps,
    not at the first one's: the bias is linear in eps (docs/identification.md), so
    at eps = 2e-4 it is twice that at 1e-4 (-0.80 % and -0.42 % of xi on one
    20-unit record with xi fitted alone; 1.89 times), within 10 %. One record and
    one stage, so that the fit compiles little."""
    jc.configure()

    def xi_error(eps):
        engine = jc.Smoothed(options=jc.SimulationOptions(rtol=1e-6, atol=1e-8), eps=eps)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            result = jc.identify(clean_records[1:2], RIG, fit=("xi",),
                                 options=jc.IdentifyOptions(engine=engine, weights=(1.0,)))
        assert result.converged and float(result.engine.eps) == eps
        return result.values[0] / TRUE["xi"] - 1

    first = xi_error(1e-4)
    with _traces() as traced:
        second = xi_error(2e-4)
    assert traced == []
    assert first < 0 and second / first == pytest.approx(2.0, rel=0.1)


@pytest.mark.numerics
@pytest.mark.study
@pytest.mark.long
def test_the_exact_engine_fits_exact_records_without_the_smoothing_bias(clean_records,
                                                                       tmp_path, capsys):
    """Records of the exact model refitted by the exact model, by `jaxchain identify
    --engine exact` on the records as CSV files: no smoothing bias is left, so the
    parameters come back to 1e-6 relative (the smoothed fit's bias is 1e-3 at eps =
    1e-5, below), and the result says which model it fitted. At the tolerances of
    the Jacobian's test above."""
    files = [str(jc.write_record(r, tmp_path / f"rig_{i}.csv"))
             for i, r in enumerate(clean_records)]
    capsys.readouterr()
    assert jc.main(["identify", *files, "--engine", "exact", "--offsets", "--rtol", "1e-10",
                    "--atol", "1e-12", "--json", "--out", str(tmp_path / "out")]) == 0
    out = capsys.readouterr().out
    doc = json.loads(out[out.index("{"):])
    assert doc["engine"] == "exact" and doc["eps"] is None and doc["converged"]
    for label, entry in doc["parameters"].items():
        assert entry["value"] == pytest.approx(TRUE[label], rel=1e-6), label


@pytest.mark.study
@pytest.mark.numerics
@pytest.mark.long
def test_noise_free_records_give_the_parameters_and_offsets(clean_records):
    """Without noise the parameters come back within the smoothing's bias, which
    is linear in eps (2.0 %, 0.24 %, 0.03 % of xi at eps = 1e-3, 1e-4, 1e-5 on
    60-unit records): 1e-3 relative at the default eps = 1e-5. On these 20-unit
    records the bias of xi is larger, 9.96e-4 relative (9.97e-4 under the second
    rounding): the bound holds with almost no margin, and a change of the fit
    that moves the bias of xi by 0.4 % of itself fails it. The sensor offsets
    (0, 0.2, -0.1), relative to the first record's, are found within 1e-3."""
    offsets = (0.0, 0.2, -0.1)
    records = _noisy(clean_records, np.random.default_rng(0), noise=0.0, offsets=offsets)
    result = _fit(records)
    assert result.converged
    for label, value in zip(result.labels, result.values):
        assert value == pytest.approx(TRUE[label], rel=1e-3), label
    np.testing.assert_allclose(result.offsets, offsets, atol=1e-3)
    # the printed table says which model was fitted (identify's command prints it)
    assert result.summary().splitlines()[0] == "fitted by the smoothed model, eps = 1e-05"


@pytest.mark.numerics
@pytest.mark.slow
@pytest.mark.study
@pytest.mark.long
def test_standard_errors_cover_the_truth_as_often_as_they_should(clean_records):
    """Ten noise draws (0.5 % of the amplitude) of the same records, four
    parameters and two offsets each: 60 intervals of +-2 standard errors, which
    should cover the true value 95.4 % of the time (57.3 of 60; binomial standard
    deviation 1.6, more as the intervals of one draw are correlated). The test
    asks for at least 50 (4.5 binomial standard deviations below), and for the
    z-scores' root mean square (1 for honest errors) to lie in [0.6, 1.5]: too
    small standard errors fail the first, too large the second."""
    rng = np.random.default_rng(2026)
    z = []
    for _ in range(10):
        result = _fit(_noisy(clean_records, rng))
        truth = np.array([TRUE[label] for label in result.labels])
        z.extend((result.values - truth) / result.standard_errors)
        z.extend(result.offsets[1:] / result.offset_errors[1:])
    z = np.asarray(z)
    assert np.sum(np.abs(z) < 2) >= 50, z
    assert 0.6 <= np.sqrt(np.mean(z**2)) <= 1.5, z


@pytest.mark.numerics
@pytest.mark.slow
@pytest.mark.study
@pytest.mark.long
def test_stribeck_records_are_attributed_to_the_stribeck_law():
    """Records made with a Stribeck law of Gaussian decay (delta = 2), which the
    exponential law cannot take: on held-out records the Stribeck fit's residual
    is the smaller, and its information criteria too. Three records fitted with
    offsets, as in `_fit` (the fit of the exponential law is then the program that
    `test_noise_free_records...` compiled), and three held out."""
    jc.configure()
    law = jc.Stribeck(mu_s=1.0, mu_c=0.55, v_s=0.45, delta=2.0, viscous=0.0)
    rig = jc.ChainParams(n_osc=1, xi=0.04, friction=law)
    rng = np.random.default_rng(7)
    records = _noisy([jc.reference_record(rig, v, T_END, DT)
                      for v in (0.4, 0.55, 0.7, 0.85, 1.0, 1.15)], rng, offsets=(0.0,) * 6)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rows = jc.compare_laws(records[::2], records[1::2], jc.ChainParams(n_osc=1),
                               ["exponential", "stribeck"], offsets=True)
    by_law = {row["law"]: row for row in rows}
    assert by_law["stribeck"]["best"] and not by_law["exponential"]["best"]
    assert by_law["stribeck"]["held_out_rms"] < 0.5 * by_law["exponential"]["held_out_rms"]
    assert by_law["stribeck"]["aic"] < by_law["exponential"]["aic"]
