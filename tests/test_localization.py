"""Linear (Anderson) localization of the undamped chain, against the analytic
weak-disorder results and the closed-form modes of the homogeneous chain."""

import numpy as np
import pytest
from scipy.special import gamma as Gamma

import jaxchain as jc

ETA = 0.01


def passband_frequency(eta_c, theta):
    """omega^2 = 1 + 2 eta_c (1 - cos theta): the homogeneous chain's passband."""
    return 1 + 2 * eta_c * (1 - np.cos(theta))


def weak_disorder_localization(sigma, eta_c, theta):
    """gamma = sigma^2 / (8 eta_c^2 sin^2 theta), the weak-disorder result
    (Thouless; Kramer & MacKinnon, Rep. Prog. Phys. 56 (1993) 1469)."""
    return sigma**2 / (8 * eta_c**2 * np.sin(theta) ** 2)


@pytest.mark.numerics
def test_weak_disorder_inside_the_band():
    """Away from the band centre and edges, sigma << eta_c: the transfer-matrix
    exponent agrees with sigma^2 / (8 eta_c^2 sin^2 theta) within 4 standard errors
    (the next order is (sigma / eta_c)^2 smaller, below the error here)."""
    sigma = 0.1 * ETA
    for theta in (np.pi / 3, 2 * np.pi / 3, np.pi / 4):
        g, err = jc.localization_factor(ETA, sigma, passband_frequency(ETA, theta),
                                        cells=400_000)
        expected = weak_disorder_localization(sigma, ETA, theta)
        assert err < 0.02 * expected
        assert abs(g - expected) < 4 * err


@pytest.mark.numerics
def test_band_centre_kappus_wegner_anomaly():
    """At theta = pi/2 the second-order result is off by the Kappus-Wegner factor
    8 Gamma(3/4)^2 / Gamma(1/4)^2 = 0.9139 (Kappus & Wegner, Z. Phys. B 45 (1981)
    15; Derrida & Gardner, J. Phys. 45 (1984) 1283)."""
    sigma = 0.1 * ETA
    g, err = jc.localization_factor(ETA, sigma, passband_frequency(ETA, np.pi / 2),
                                    cells=400_000)
    factor = 8 * Gamma(0.75) ** 2 / Gamma(0.25) ** 2
    expected = factor * weak_disorder_localization(sigma, ETA, np.pi / 2)
    assert abs(g - expected) < 4 * err + 0.005 * expected
    assert abs(g / weak_disorder_localization(sigma, ETA, np.pi / 2) - 1) > 0.05


@pytest.mark.numerics
def test_outside_the_band_the_exponent_is_the_evanescent_decay():
    """Below the passband (omega^2 < 1) the homogeneous chain's waves decay like
    exp(-kappa n), cosh kappa = 1 + (1 - omega^2) / (2 eta_c); weak disorder
    changes kappa by O(sigma^2)."""
    omega2 = 1 - 0.02
    g, _ = jc.localization_factor(ETA, 1e-5, omega2, cells=20_000)
    assert abs(g - np.arccosh(1 + (1 - omega2) / (2 * ETA))) < 1e-4


@pytest.mark.numerics
def test_inverse_participation_ratio_of_the_homogeneous_open_chain():
    """Free ends: modes cos((n + 1/2) k pi / N); the uniform mode and the mode
    k = N/2 (|phi_n| all equal) have IPR 1/N, the others 3 / (2 N). Mistuning of
    4 eta_c localizes them (IPR well above)."""
    n = 12
    chain = jc.ChainParams(n_osc=n, boundary="free")
    omega2, ipr = jc.inverse_participation_ratio(chain)
    k = np.arange(n)
    np.testing.assert_allclose(omega2, 1 + 2 * ETA * (1 - np.cos(k * np.pi / n)), atol=1e-12)
    np.testing.assert_allclose(ipr, np.where((k == 0) | (2 * k == n), 1 / n, 1.5 / n), atol=1e-9)
    _, mistuned = jc.inverse_participation_ratio(jc.mistune(chain, 4 * ETA, 0))
    assert mistuned.mean() > 2 * ipr.mean()


def _forced_ring_response(eta_c, omega, damping, n=201):
    """|x_n| of the damped ring driven at oscillator 0, by a dense complex solve of
    (K - omega^2 + i omega c) x = e_0 (numpy, independent of the transfer matrix)."""
    k = np.asarray(jc.stiffness_matrix(jc.ChainParams(n_osc=n, eta_c=eta_c)))
    force = np.zeros(n)
    force[0] = 1.0
    return np.abs(np.linalg.solve(k - omega**2 * np.eye(n) + 1j * omega * damping
                                  * np.eye(n), force))


@pytest.mark.numerics
@pytest.mark.parametrize("omega2, damping", [(1.0099, 0.0502), (0.98, 0.0), (1.02, 0.03)])
def test_damped_decay_is_the_forced_chain_s_envelope(omega2, damping):
    """The decay per cell of the driven damped ring (inside the passband with
    damping, below it without) matches `damped_decay`; at sigma = 0,
    `localization_factor` is the undamped value exactly."""
    x = _forced_ring_response(ETA, np.sqrt(omega2), damping)
    measured = np.log(x[3] / x[4])
    assert abs(measured - jc.damped_decay(ETA, omega2, damping)) < 1e-6
    if damping == 0:
        g, err = jc.localization_factor(ETA, 0.0, omega2)
        assert err == 0 and abs(g - measured) < 1e-6


def test_bad_arguments():
    with pytest.raises(ValueError, match="sigma"):
        jc.localization_factor(ETA, -0.01, 1.0)
    with pytest.raises(ValueError, match="eta_c"):
        jc.damped_decay(0.0, 1.0, 0.1)
    with pytest.raises(ValueError, match="eta_c"):
        jc.localization_factor(-1.0, 0.01, 1.0)
    with pytest.raises(ValueError, match="batches"):
        jc.localization_factor(ETA, 0.01, 1.0, batches=1)
