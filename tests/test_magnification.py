"""The forced mistuned ring (`jaxchain magnification`): its peaks by harmonic
balance against the linear ring's analytic response, Whitehead's bound, the draws
vmapped against one at a time, and the mean magnification's derivative in the
friction coefficient against central differences."""

import jax
import numpy as np
import pytest
from scipy.optimize import minimize_scalar

import jaxchain as jc

N, R, A, XI = 4, 1, 4e-3, 2e-3
FREQUENCIES = np.linspace(0.96, 1.06, 81)
LINEAR = jc.ChainParams(n_osc=N, xi=XI, eta_c=0.01, v_d=0.0, friction=jc.Coulomb(mu=0.0),
                        forcing=jc.Forcing.engine_order(N, R, A, 1.0))
HB = jc.HarmonicBalance(eps=0.05, harmonics=1, time_samples=64, linear_solver="lu",
                        newton_tol=1e-10, newton_steps=8)


def analytic_peak(stiffness):
    """The largest amplitude of the linear ring k_n x_n + eta_c (2 x_n - x_n+1 -
    x_n-1) + 2 xi x_n' + x_n'' = A cos(Omega t + 2 pi R n / N) over Omega: the
    complex amplitudes by a direct solve, maximised per oscillator by scipy's
    bounded Brent around the best of a fine grid."""
    eye = np.eye(N)
    k = np.diag(stiffness) + 0.01 * (2 * eye - np.roll(eye, 1, 0) - np.roll(eye, -1, 0))
    f = A * np.exp(2j * np.pi * R * np.arange(N) / N)

    def amplitude(omega, n):
        return np.abs(np.linalg.solve(k - omega**2 * eye + 2j * XI * omega * eye, f))[n]

    grid = np.linspace(FREQUENCIES[0], FREQUENCIES[-1], 4001)
    best = []
    for n in range(N):
        values = [amplitude(w, n) for w in grid]
        i = int(np.argmax(values))
        r = minimize_scalar(lambda w: -amplitude(w, n), bounds=(grid[max(i - 1, 0)],
                            grid[min(i + 1, grid.size - 1)]), method="bounded",
                            options={"xatol": 1e-12})
        best.append(-r.fun)
    return max(best)


@pytest.fixture(scope="module")
def linear_peaks():
    chains = jc.mistuned_lanes(LINEAR, 0.01, 3)
    return chains, jc.response_peaks(chains, HB, FREQUENCIES)


@pytest.mark.numerics
@pytest.mark.study
def test_the_linear_ring_s_peaks_are_the_analytic_response_s(linear_peaks):
    """H = 1 is exact on the linear ring: every lane's peak (the tuned ring and three
    draws at sigma = eta_c) equals the direct solve's maximised over the frequency,
    to 1e-8 relative; the magnification stays under Whitehead's bound."""
    chains, peaks = linear_peaks
    assert peaks.converged.all()
    for lane in range(4):
        stiffness = np.broadcast_to(np.asarray(chains.stiffness)[lane], (N,))
        assert abs(peaks.amplitude[lane] / analytic_peak(stiffness) - 1) < 1e-8
    assert np.all(peaks.amplitude[1:] / peaks.amplitude[0] <= jc.whitehead_bound(N))


@pytest.mark.numerics
@pytest.mark.study
def test_vmapped_lanes_equal_the_lanes_run_one_at_a_time(linear_peaks):
    """The batch's peaks against each lane's own run (another compiled program):
    equal to the Newton tolerance."""
    chains, peaks = linear_peaks
    for lane in (0, 2):
        alone = jc.response_peaks(jax.tree_util.tree_map(lambda a: a[lane:lane + 1], chains),
                                  HB, FREQUENCIES)
        assert abs(alone.amplitude[0] / peaks.amplitude[lane] - 1) < 1e-8
        assert abs(alone.frequency[0] - peaks.frequency[lane]) < 1e-6


@pytest.mark.study
@pytest.mark.numerics
@pytest.mark.slow
def test_the_mean_magnification_s_derivative_in_mu_against_central_differences():
    """With friction dampers (mu = 1e-3 against the force 4e-3): the derivative of
    the mean magnification over 3 draws in mu, by jax.grad and jax.jvp through each
    peak's orbit, against central differences of the whole study (sweep and
    peaks again at mu (1 +- 1e-3)), within 1e-4 relative."""
    damped = jc.ChainParams(n_osc=N, xi=XI, eta_c=0.01, v_d=0.0, friction=jc.Coulomb(mu=1e-3),
                            forcing=jc.Forcing.engine_order(N, R, A, 1.0))
    result = jc.magnification_gradient(damped, 0.01, 3, FREQUENCIES, HB, relative_step=1e-3)
    assert result["relative_error"] < 1e-4, result
    assert abs(result["forward"] / result["gradient"] - 1) < 1e-10, result
    assert result["gradient"] != 0


def test_bad_input_is_refused_by_name():
    with pytest.raises(jc.ValidationError, match="forced chain"):
        jc.magnification_gradient(jc.ChainParams(n_osc=N, friction=jc.Coulomb(mu=1e-3)),
                               0.01, 2, FREQUENCIES, HB)
    with pytest.raises(jc.ValidationError, match="frequencies"):
        jc.response_peaks(jc.mistuned_lanes(LINEAR, 0.01, 1), HB, [1.0, 0.9, 1.1])
    with pytest.raises(jc.ValidationError, match="sigmas"):
        jc.magnification_study(LINEAR, [-0.01], 2, FREQUENCIES, HB)
