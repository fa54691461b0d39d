import jax.numpy as jnp
import numpy as np
import pytest

import jaxchain as jc


def test_excited_block_grows_around_oscillator_11():
    assert np.flatnonzero(jc.excited_block(20, 1)).tolist() == [10]  # oscillator 11
    assert (np.flatnonzero(jc.excited_block(20, 3)) + 1).tolist() == [10, 11, 12]
    assert (np.flatnonzero(jc.excited_block(20, 4)) + 1).tolist() == [10, 11, 12, 13]
    assert jc.excited_block(20, 20).all()
    assert (np.flatnonzero(jc.excited_block(5, 4)) + 1).tolist() == [2, 3, 4, 5]
    assert (np.flatnonzero(jc.excited_block(4, 3)) + 1).tolist() == [2, 3, 4]
    for k in range(21):
        assert jc.excited_block(20, k).sum() == k
    with pytest.raises(ValueError, match="n_excited"):
        jc.excited_block(20, 21)


def test_eq8_and_eq10_values():
    p = jc.ChainParams(n_osc=4, v_d=1.5)
    mask = np.array([False, True, True, False])
    law = p.friction
    mu = law.mu_d + (law.mu_st - law.mu_d) * np.exp(-1.5 / law.v0)  # F(-v_d) = mu(v_d)
    y8 = jc.OutOfPhaseExcitation.eq8(mask)(p)
    assert np.allclose(y8[0], mu + np.array([0, 2, -2, 0]), rtol=1e-12)  # 2 (-1)^n
    assert np.all(y8[1] == 0)
    y10 = jc.OutOfPhaseExcitation.eq10(mask)(p)
    assert np.allclose(y10[0], -mu + np.array([0, 2, -2, 0]), rtol=1e-12)  # F(+v_d)
    assert np.allclose(y10[1], 0.56)


def test_localized_family_rows_and_bad_family():
    fam = jc.localized_family(6, "eq8")
    assert fam.excited.shape == (6, 6)
    assert np.asarray(fam.excited).sum(1).tolist() == [1, 2, 3, 4, 5, 6]
    with pytest.raises(ValueError, match="ics"):
        jc.localized_family(6, "eq9")


def test_given_state_checks_shape():
    p = jc.ChainParams(n_osc=3)
    assert jc.GivenState(jnp.arange(6.0))(p).shape == (2, 3)
    with pytest.raises(ValueError, match="y0"):
        jc.GivenState(jnp.zeros((2, 4)))(p)
    with pytest.raises(ValueError, match="excited"):
        jc.OutOfPhaseExcitation.eq8(np.ones(4, bool))(p)
