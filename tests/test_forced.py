"""A forced chain (`Forcing`): harmonic balance and shooting against the analytic
forced response of the linear chain (friction off), and harmonic balance against
an independent event-driven solution of the forced oscillator with Coulomb
friction (Den Hartog's setting, Trans. ASME 53 (1931): continuous motion, no
stops), built here from scipy."""

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.linalg import expm
from scipy.optimize import brentq

import jaxchain as jc

N = 5
OMEGA = 1.05


@pytest.fixture(scope="module")
def linear_ring():
    """A mistuned ring of five without friction (Coulomb mu = 0), standing still
    (v_d = 0), under an engine-order-2 travelling wave; its analytic response
    X = (K - Omega^2 + i Omega C)^-1 F e^{i phase} and its monodromy matrix
    exp(A T), A = [[0, I], [-K, -C]]."""
    forcing = jc.Forcing.engine_order(N, 2, 0.1, OMEGA)
    params = jc.mistune(jc.ChainParams(n_osc=N, xi=0.02, eta_c=0.05, v_d=0.0,
                                       friction=jc.Coulomb(0.0), forcing=forcing), 0.05, 3)
    k = np.asarray(jc.stiffness_matrix(params))
    c = 2 * 0.02 * np.eye(N)
    x = np.linalg.solve(k - OMEGA**2 * np.eye(N) + 1j * OMEGA * c,
                        0.1 * np.exp(1j * np.asarray(forcing.phase)))
    y0 = np.stack([x.real, (1j * OMEGA * x).real])
    a = np.block([[np.zeros((N, N)), np.eye(N)], [-k, -c]])
    multipliers = np.linalg.eigvals(expm(a * 2 * np.pi / OMEGA))
    return params, y0, np.abs(x), multipliers


def _set_distance(a, b):
    """The largest distance from a value of either set to the nearest of the other
    (the sets of multipliers, in whatever order)."""
    d = np.abs(np.asarray(a)[:, None] - np.asarray(b)[None, :])
    return max(d.min(0).max(), d.min(1).max())


@pytest.mark.numerics
@pytest.mark.study
def test_harmonic_balance_gives_the_linear_response_exactly_with_one_harmonic(linear_ring):
    """H = 1 holds the linear chain's response exactly: the start state to 1e-12
    from rest as the guess, the period the force's, and the Floquet multipliers
    (none trivial: the chain is forced) those of exp(A T) to 1e-8."""
    params, y0, amplitudes, multipliers = linear_ring
    orbit = jc.periodic_orbit(params, (np.zeros((2, N)), 6.0),
                              jc.HarmonicBalance(harmonics=1))
    assert np.max(np.abs(np.asarray(orbit.y0) - y0)) < 1e-12
    assert abs(float(orbit.period) - 2 * np.pi / OMEGA) < 1e-12
    assert int(orbit.trivial) == 2 * N  # past the end: no trivial multiplier
    assert _set_distance(orbit.multipliers, multipliers) < 1e-8
    assert bool(orbit.stable)


@pytest.mark.numerics
@pytest.mark.study
def test_shooting_on_the_forced_smoothed_engine_gives_the_linear_response(linear_ring):
    """Shooting integrates the forced field from t = 0: its orbit is the analytic
    response to 1e-8 (the flow's tolerances 1e-10, 1e-12), its multipliers exp(A T)'s
    to 1e-7."""
    params, y0, amplitudes, multipliers = linear_ring
    orbit = jc.periodic_orbit(params, (np.zeros((2, N)), 6.0), jc.Shooting())
    assert np.max(np.abs(np.asarray(orbit.y0) - y0)) < 1e-8
    assert np.max(np.abs(np.asarray(orbit.amplitudes) - amplitudes)) < 1e-6
    assert _set_distance(orbit.multipliers, multipliers) < 1e-7


# --- the forced oscillator with Coulomb friction ---

XI, MU, FORCE = 0.05, 0.3, 1.0


def _half_period(t0, x0, omega, force):
    """The exact motion from the turning point (x0 > 0, x' = 0) at t0 over half a
    period, sliding backwards: x'' + 2 xi x' + x = F cos(Omega t) + mu."""
    def field(t, y):
        return [y[1], -2 * XI * y[1] - y[0] + force * np.cos(omega * t) + MU]
    return solve_ivp(field, (t0, t0 + np.pi / omega), [x0, 0.0], rtol=1e-12, atol=1e-13,
                     dense_output=True)


def coulomb_response(omega, force=FORCE):
    """The amplitude of the symmetric steady motion without stops, x(t + T/2) =
    -x(t), found as Den Hartog's: the turning point (t0, x0) from which half a
    period ends at (-x0, 0). x0 is affine in the end position for a fixed t0; t0 is
    the root of the end velocity. Returns (x0, whether the turning point is a stop:
    |F cos(Omega t0) - x0| <= mu)."""
    def x0_of(t0):
        a, b = (_half_period(t0, x, omega, force).y[0, -1] + x for x in (1.0, 2.0))
        return 1.0 - a / (b - a)

    def end_velocity(t0):
        return _half_period(t0, x0_of(t0), omega, force).y[1, -1]

    ts = np.linspace(0.0, 2 * np.pi / omega, 41)
    vs = [end_velocity(t) for t in ts]
    for i in range(40):
        if np.sign(vs[i]) != np.sign(vs[i + 1]) and x0_of(ts[i]) > 0:
            t0 = brentq(end_velocity, ts[i], ts[i + 1], xtol=1e-13)
            x0 = x0_of(t0)
            motion = _half_period(t0, x0, omega, force)
            v = motion.sol(np.linspace(t0, t0 + np.pi / omega, 2001))[1]
            if x0 > 0 and np.all(v[1:-1] < 0):
                return x0, abs(force * np.cos(omega * t0) - x0) <= MU
    raise AssertionError(f"no symmetric motion found at Omega = {omega}")


def coulomb_motion(omega, force, periods=200):
    """The amplitude of the steady motion, stops included, by event-driven
    integration (scipy's solve_ivp with events): slip with the friction force
    -mu sign(x') until x' = 0; there the oscillator stops if the force it needs,
    |F cos(Omega t) - x|, is at most mu (static = kinetic, Coulomb's law), and stays
    until that force reaches mu. From rest at x = 0 over `periods` periods (the
    viscous damping xi = 0.05 settles the transient); the amplitude is half of
    the peak-to-peak of x over the last period, and whether it stopped there."""
    period = 2 * np.pi / omega
    t, x, v, direction = 0.0, 0.0, 0.0, 0.0
    t_end, xs, stopped = periods * period, [], False

    def needed(t, x):
        return force * np.cos(omega * t) - x

    while t < t_end:
        if direction == 0.0:  # stopped: until the needed force reaches mu
            ts = np.linspace(t, min(t + period, t_end), 400)
            over = np.flatnonzero(np.abs(needed(ts, x)) > MU)
            if t >= t_end - period:
                xs.append(x)
                stopped = True
            if over.size == 0:
                t = ts[-1]
                continue
            i = over[0]
            t = brentq(lambda s: abs(needed(s, x)) - MU, ts[max(i - 1, 0)], ts[i], xtol=1e-14) \
                if i > 0 else ts[0]
            direction = np.sign(needed(t, x))
            continue

        def field(s, y, d=direction):
            return [y[1], -2 * XI * y[1] - y[0] + force * np.cos(omega * s) - MU * d]

        def halt(s, y):
            return y[1]
        halt.terminal, halt.direction = True, -direction
        sol = solve_ivp(field, (t, t_end), [x, v], events=halt, rtol=1e-11, atol=1e-12,
                        dense_output=True, max_step=period / 50)
        tail = np.linspace(max(t, t_end - period), sol.t[-1], 200)
        if sol.t[-1] > t_end - period:
            xs.extend(sol.sol(tail[tail >= t_end - period])[0])
        t, (x, v) = sol.t[-1], sol.y[:, -1]
        if sol.status == 1:  # the velocity vanished: stop or reverse
            v = 0.0
            direction = 0.0 if abs(needed(t, x)) <= MU else np.sign(needed(t, x))
    return 0.5 * (max(xs) - min(xs)), stopped


@pytest.mark.study
@pytest.mark.numerics
def test_forced_coulomb_oscillator_against_the_exact_motion_without_stops():
    """The friction damper (v_d = 0, mu_st = mu_d: `Coulomb`) through resonance:
    harmonic balance at H = 64 (4096 time samples, eps 1e-4) within 1.5e-3 relative
    of the exact amplitude, where the motion has no stops. The friction force jumps
    where the velocity has a kink, so the error falls only as 1/H: H = 128 halves it
    (to within 20 %). Marked `study` (about a minute: four solves at 4096 and 8192
    samples): CI runs it in its study step."""
    errors = {}
    for omega in (0.6, 1.0, 1.5):
        exact, stops = coulomb_response(omega)
        assert not stops
        params = jc.ChainParams(n_osc=1, xi=XI, v_d=0.0, friction=jc.Coulomb(MU),
                                forcing=jc.Forcing(FORCE, omega))
        for h in (64, 128) if omega == 1.5 else (64,):
            method = jc.HarmonicBalance(eps=1e-4, harmonics=h, time_samples=64 * h)
            # the period guess is the force's, whatever is given
            orbit = jc.periodic_orbit(params, (np.zeros((2, 1)), 1.0), method)
            errors[omega, h] = abs(float(orbit.amplitudes[0]) / exact - 1)
    assert max(e for (_, h), e in errors.items() if h == 64) < 1.5e-3, errors
    assert 0.4 < errors[1.5, 128] / errors[1.5, 64] < 0.6, errors


def test_a_loose_forced_run_keeps_its_energy_balance():
    """A run at loose tolerances is audited by its energy balance; the force's power
    is in it: the forced linear oscillator (friction off) reaches the analytic
    amplitude F / sqrt((1 - Omega^2)^2 + (2 xi Omega)^2) to 1e-3 (rtol 1e-4) with
    status ok, not a failed balance."""
    params = jc.ChainParams(n_osc=1, v_d=0.0, friction=jc.Coulomb(0.0),
                            forcing=jc.Forcing(0.1, 0.8))
    obs = jc.simulate(params, np.zeros((2, 1)), throw=False, options=jc.SimulationOptions(
        t_end=400.0, transient=300.0, rtol=1e-4, atol=1e-6))
    assert int(obs.status) == jc.Status.ok
    exact = 0.1 / np.sqrt((1 - 0.8**2) ** 2 + (2 * 0.05 * 0.8) ** 2)
    assert abs(float(obs.amplitudes[0]) / exact - 1) < 1e-3


def test_the_exact_engine_refuses_a_forced_chain():
    params = jc.ChainParams(n_osc=2, v_d=0.5, forcing=jc.Forcing(0.1, 1.0))
    with pytest.raises(ValueError, match="forcing: the exact engine"):
        jc.Exact().flow(params, np.zeros((2, 2)), 1.0)


# --- the command line ---


@pytest.mark.study
def test_the_response_command_draws_the_linear_resonance_curve(tmp_path):
    """`jaxchain response` on the linear oscillator (friction off, H = 1): every
    point's amplitude is the analytic F / sqrt((1 - Omega^2)^2 + (2 xi Omega)^2) to
    1e-6 (the amplitude is read as the largest of 4096 samples of the period:
    1 - cos(pi / 4096) = 3e-7), the curve is stable, without folds, and it peaks
    at the resonance sqrt(1 - 2 xi^2) to within its step."""
    import xarray as xr

    out = tmp_path / "out"
    assert jc.main(["response", "--force", "0.1,0.8", "--friction", "coulomb:mu=0",
                    "--to", "1.2", "--harmonics", "1", "--out", str(out), "--json",
                    "--no-progress"]) == 0
    with xr.open_dataset(out / "response.nc") as ds:
        omega, amplitude = ds["frequency"].values, ds["max_amplitude"].values
        exact = 0.1 / np.sqrt((1 - omega**2) ** 2 + (2 * 0.05 * omega) ** 2)
        np.testing.assert_allclose(amplitude, exact, rtol=1e-6)
        assert bool(ds["stable"].all()) and np.size(ds.attrs["fold_frequencies"]) == 0
        assert omega[0] == 0.8 and omega[-1] >= 1.2 and ds.attrs["friction"] == "coulomb"
        peak = int(np.argmax(amplitude))
        assert omega[peak - 1] < np.sqrt(1 - 2 * 0.05**2) < omega[peak + 1]
    assert (out / "response.png").exists() and (out / "response.json").exists()


@pytest.mark.parametrize("argv, says", [
    (["response", "--to", "1.2"], "--force: give the force"),
    (["response", "--force", "0.1,0.8"], "--to: give the other end"),
    (["response", "--force", "0.1"], "--force: expected A,OMEGA"),
    (["response", "--force=-0.1,0.8", "--to", "1"], "Forcing.amplitude"),
])
def test_bad_response_options_exit_2_in_one_line(argv, says, capsys, tmp_path):
    from helpers import assert_usage_error

    assert_usage_error(argv + ["--out", str(tmp_path)], says, capsys)


def test_a_forced_chain_file_is_refused_by_a_command_without_forcing(capsys, tmp_path):
    from helpers import assert_usage_error

    chain = tmp_path / "forced.toml"
    chain.write_text("n_osc = 2\nforce_amplitude = 0.1\nforce_frequency = 1.0\n")
    assert_usage_error(["localized", "--chain", str(chain), "--out", str(tmp_path / "o")],
                       "taken by jaxchain response only", capsys)
