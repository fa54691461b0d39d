import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import jaxchain as jc


def smoothed_friction_force(p, v_rel, eps):
    """The smoothed engine's friction force at each relative velocity of `v_rel`, read
    off its vector field (`jc.Smoothed(eps=eps).field`): one oscillator of `p`'s
    friction law and load with xi = 0, at x = 0, whose acceleration is then the
    friction force alone. The belt and the oscillator's speed are chosen so that
    x' - v_d is `v_rel` exactly: v_d = |v_rel| (1 at 0) and x' = v_d + v_rel, which
    is 0 or 2 v_rel, and 2 v_rel - v_rel is exact."""
    forces = []
    for v in np.ravel(np.asarray(v_rel, dtype=float)):
        v_d = abs(v) if v != 0 else 1.0
        one = jc.ChainParams(n_osc=1, xi=0.0, v_d=v_d, friction=p.friction, load=p.load)
        y = jnp.array([[0.0], [v_d + v]])
        assert float(y[1, 0]) - v_d == v  # the relative velocity asked for, exactly
        forces.append(jc.Smoothed(eps=eps).field(one, y)[1, 0])
    return jnp.reshape(jnp.stack(forces), np.shape(v_rel))


@pytest.mark.numerics
def test_friction_coefficient_limits():
    p = jc.ChainParams()
    assert float(jc.friction_coefficient(p, 0.0)) == p.friction.mu_st
    assert np.isclose(float(jc.friction_coefficient(p, 50.0)), p.friction.mu_d, rtol=1e-12)
    # eq. (1) at |v_rel| = v0: mu_d + (mu_st - mu_d)/e, on both sides
    expected = p.friction.mu_d + (p.friction.mu_st - p.friction.mu_d) / np.e
    v0 = p.friction.v0
    assert np.allclose(jc.friction_coefficient(p, jnp.array([-v0, v0])), expected)


@pytest.mark.numerics
def test_smoothed_force_tends_to_coulomb_law_away_from_zero():
    p, eps = jc.ChainParams(), 1e-3
    v = jnp.array([-2.0, -0.5, 0.5, 2.0])
    coulomb = -jc.friction_coefficient(p, v) * jnp.sign(v)
    assert np.allclose(smoothed_friction_force(p, v, eps), coulomb, rtol=1e-12)
    assert float(smoothed_friction_force(p, 0.0, eps)) == 0.0
    # slope at zero is mu_st / eps: the stiffness of the smoothed stick phase
    h = 1e-9
    slope = (smoothed_friction_force(p, h, eps)
             - smoothed_friction_force(p, -h, eps)) / (2 * h)
    assert np.isclose(float(slope), -p.friction.mu_st / eps, rtol=1e-5)


@pytest.mark.numerics
@settings(max_examples=50, deadline=None)
# Subnormal speeds are left out: XLA's CPU kernels treat subnormal inputs as zero
# (denormals-are-zero) on some processors, so the helper's exact relative velocity
# x' - v_d would not be the one asked for (CI drew v = 1.1e-308 and got 2.2e-308).
@given(v=st.floats(-100, 100, allow_subnormal=False), eps=st.floats(1e-5, 1.0))
def test_smoothed_force_is_odd_and_bounded_by_mu_st(v, eps):
    p = jc.ChainParams()
    f = float(smoothed_friction_force(p, v, eps))
    assert abs(f) <= p.friction.mu_st
    assert f == -float(smoothed_friction_force(p, -v, eps))
    assert f * v <= 0  # friction always opposes the relative motion
