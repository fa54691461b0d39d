"""The paper's central result, at full size: the staircase of Fig. 4 / Fig. 3(b)."""

import numpy as np
import pytest

import jaxchain as jc


@pytest.mark.slow
def test_fig4_staircase_at_vd_1_5():
    """N = 20, v_d = 1.5, eq. (8) with k = 1..20 excited, t in [0, 15000], observed
    after 10000. The paper finds k oscillators on the HALC for every k (its
    Fig. 4), each contributing about 1.2 to E (Fig. 3(b)). We require it for
    k <= 18; for k = 19 the two unexcited oscillators may be pulled onto the HALC."""
    ds = jc.ensemble(jc.ChainParams(), [1.5], jc.localized_family(20), progress=False)
    n_halc, energy = ds["n_halc"].values[0], ds["energy"].values[0]
    assert np.all(ds["status"].values == 0)
    assert n_halc[:18].tolist() == list(range(1, 19))
    assert np.all((energy / n_halc > 1.1) & (energy / n_halc < 1.3))
    order = np.argsort(n_halc, kind="stable")
    assert np.all(np.diff(energy[order][n_halc[order] < 20]) > 0)
