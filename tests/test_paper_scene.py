"""The paper's central result, at full size: the staircase of Fig. 4 / Fig. 3(b)."""

import numpy as np
import pytest

import jaxchain as jc
from helpers import scipy_stick_slip_cycle


@pytest.mark.slow
def test_fig4_staircase_at_vd_1_5():
    """N = 20, v_d = 1.5, eq. (8) with k = 1..20 excited, t in [0, 15000], observed
    after 10000. The paper finds k oscillators on the HALC for every k (its
    Fig. 4), each contributing about the same to E (Fig. 3(b)). We require it for
    k <= 18; for k = 19 the two unexcited oscillators may be pulled onto the HALC.

    Each oscillator on the HALC carries about the energy A^2/2 of the single
    oscillator's non-smooth stick-slip cycle (scipy, `scipy_stick_slip_cycle`):
    E / n_HALC lies within 10 % of it, the coupling eta_c = 0.01 and the small
    oscillations of the neighbours on steady sliding making up the difference."""
    ds = jc.ensemble(jc.ChainParams(), [1.5], jc.localized_family(20), progress=False)
    n_halc, energy = ds["n_halc"].values[0], ds["energy"].values[0]
    assert np.all(ds["status"].values == 0)
    assert n_halc[:18].tolist() == list(range(1, 19))
    single = 0.5 * scipy_stick_slip_cycle(jc.ChainParams(n_osc=1))[0] ** 2
    assert np.all(np.abs(energy / n_halc / single - 1) < 0.1)
    order = np.argsort(n_halc, kind="stable")
    assert np.all(np.diff(energy[order][n_halc[order] < 20]) > 0)
