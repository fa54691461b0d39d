"""Linear (Anderson) localization of the undamped chain, against the analytic
weak-disorder results and the closed-form modes of the homogeneous chain."""

import numpy as np
import pytest
from scipy.special import gamma as Gamma

import jaxchain as jc

ETA = 0.01


def test_weak_disorder_inside_the_band():
    """Away from the band centre and edges, sigma << eta_c: the transfer-matrix
    exponent agrees with sigma^2 / (8 eta_c^2 sin^2 theta) within 4 standard errors
    (the next order is (sigma / eta_c)^2 smaller, below the error here)."""
    sigma = 0.1 * ETA
    for theta in (np.pi / 3, 2 * np.pi / 3, np.pi / 4):
        g, err = jc.localization_factor(ETA, sigma, jc.passband_frequency(ETA, theta),
                                        cells=400_000)
        expected = jc.weak_disorder_localization(sigma, ETA, theta)
        assert err < 0.02 * expected
        assert abs(g - expected) < 4 * err


def test_band_centre_kappus_wegner_anomaly():
    """At theta = pi/2 the second-order result is off by the Kappus-Wegner factor
    8 Gamma(3/4)^2 / Gamma(1/4)^2 = 0.9139 (Kappus & Wegner, Z. Phys. B 45 (1981)
    15; Derrida & Gardner, J. Phys. 45 (1984) 1283)."""
    sigma = 0.1 * ETA
    g, err = jc.localization_factor(ETA, sigma, jc.passband_frequency(ETA, np.pi / 2),
                                    cells=400_000)
    factor = 8 * Gamma(0.75) ** 2 / Gamma(0.25) ** 2
    expected = factor * jc.weak_disorder_localization(sigma, ETA, np.pi / 2)
    assert abs(g - expected) < 4 * err + 0.005 * expected
    assert abs(g / jc.weak_disorder_localization(sigma, ETA, np.pi / 2) - 1) > 0.05


def test_outside_the_band_the_exponent_is_the_evanescent_decay():
    """Below the passband (omega^2 < 1) the homogeneous chain's waves decay like
    exp(-kappa n), cosh kappa = 1 + (1 - omega^2) / (2 eta_c); weak disorder
    changes kappa by O(sigma^2)."""
    omega2 = 1 - 0.02
    g, _ = jc.localization_factor(ETA, 1e-5, omega2, cells=20_000)
    assert abs(g - np.arccosh(1 + (1 - omega2) / (2 * ETA))) < 1e-4


def test_inverse_participation_ratio_of_the_homogeneous_open_chain():
    """Free ends: modes cos((n + 1/2) k pi / N); the uniform mode and the mode
    k = N/2 (|phi_n| all equal) have IPR 1/N, the others 3 / (2 N). Mistuning of 4 eta_c localizes them (IPR well above)."""
    n = 12
    chain = jc.ChainParams(n_osc=n, boundary="free")
    omega2, ipr = jc.inverse_participation_ratio(chain)
    k = np.arange(n)
    np.testing.assert_allclose(omega2, 1 + 2 * ETA * (1 - np.cos(k * np.pi / n)), atol=1e-12)
    np.testing.assert_allclose(ipr, np.where((k == 0) | (2 * k == n), 1 / n, 1.5 / n), atol=1e-9)
    _, mistuned = jc.inverse_participation_ratio(jc.mistune(chain, 4 * ETA, 0))
    assert mistuned.mean() > 2 * ipr.mean()


def test_bad_arguments():
    with pytest.raises(ValueError, match="sigma"):
        jc.localization_factor(ETA, 0.0, 1.0)
    with pytest.raises(ValueError, match="eta_c"):
        jc.localization_factor(-1.0, 0.01, 1.0)
    with pytest.raises(ValueError, match="batches"):
        jc.localization_factor(ETA, 0.01, 1.0, batches=1)
