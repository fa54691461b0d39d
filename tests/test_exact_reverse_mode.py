"""Derivatives of the exact engine through `simulate`: reverse mode at the defaults
refuses in one line naming the option; forward mode at the defaults and reverse
mode with that option agree with central differences of an independent scipy
event-driven model of the stick-slip cycle."""

import functools

import jax
import jax.numpy as jnp
import pytest

import jaxchain as jc
from helpers import scipy_stick_slip_cycle

#: The exact engine's defaults (`adjoint` "forward"), over a short horizon that
#: reaches the single oscillator's stick-slip cycle from its stick exit.
DEFAULTS = jc.NonsmoothOptions(t_end=40.0, transient=20.0)


def _amplitude(v_d, options):
    """The stick-slip amplitude of one oscillator at belt speed v_d by
    `simulate(..., engine="exact")`, started at the cycle's stick exit."""
    params = jc.ChainParams(n_osc=1, v_d=v_d)
    y0 = jnp.stack([jnp.atleast_1d(params.friction.mu_st - 2 * params.xi * v_d),
                    jnp.atleast_1d(v_d)])
    obs = jc.simulate(params, y0, engine=jc.Exact(options), throw=False)
    return obs.amplitudes[0]


@functools.cache
def _scipy_slope(v_d: float) -> float:
    """d amplitude / d v_d of the scipy event-driven cycle (`scipy_stick_slip_cycle`:
    DOP853 at 1e-12, the return to the belt speed and the turning points as
    events), by central differences at h = 1e-4 and 5e-5, Richardson-extrapolated
    (truncation O(h^4), noise about 1e-12 / h)."""
    def amplitude(v):
        return scipy_stick_slip_cycle(jc.ChainParams(n_osc=1, v_d=v))[0]

    def central(h):
        return (amplitude(v_d + h) - amplitude(v_d - h)) / (2 * h)

    return (4 * central(5e-5) - central(1e-4)) / 3


def test_grad_at_the_defaults_refuses_in_one_line():
    """JAX's own error ("Reverse-mode differentiation does not work for
    lax.while_loop ...") named nothing to set; the engine's names the option."""
    for reverse in (jax.grad, lambda f: lambda v: jax.vjp(f, v)[1](1.0)):
        with pytest.raises(RuntimeError) as info:
            reverse(functools.partial(_amplitude, options=DEFAULTS))(1.5)
        message = str(info.value)
        assert "\n" not in message.strip()
        assert "NonsmoothOptions(adjoint='reverse')" in message


@pytest.mark.study
@pytest.mark.slow
@pytest.mark.numerics
@pytest.mark.long
def test_forward_and_reverse_mode_agree_with_scipy_central_differences():
    """d amplitude / d v_d of the stick-slip cycle at v_d 1.5: `jax.jvp` at the
    exact engine's defaults and `jax.grad` with adjoint "reverse", within 1e-4
    (relative) of the scipy model's central differences."""
    expected = _scipy_slope(1.5)
    value, forward = jax.jvp(functools.partial(_amplitude, options=DEFAULTS), (1.5,), (1.0,))
    assert float(value) == pytest.approx(scipy_stick_slip_cycle(jc.ChainParams(n_osc=1))[0],
                                         rel=1e-5)
    reverse = jax.grad(_amplitude)(1.5, jc.NonsmoothOptions(t_end=40.0, transient=20.0,
                                                            adjoint="reverse"))
    assert float(forward) == pytest.approx(expected, rel=1e-4)
    assert float(reverse) == pytest.approx(expected, rel=1e-4)
