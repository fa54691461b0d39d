"""The smoothed engine's integration parts below the public surface, each checked on
its own:

- the private parts of diffrax and equinox that jaxchain uses (`jaxchain._engine.compat`,
  the one module that touches them) are still there, with the layout it expects; a
  change is reported with its name, not as a wrong step size deep in a run;
- the PI step-size controller (`PIController`, which a run builds from
  `SimulationOptions.controller` and never hands out): its rules against the formulas
  of its docstring, one call of `adapt_step_size` at a time, beside diffrax's;
- the integrator of any diffrax term (`integrate`; the public `observe` integrates
  eq. (5) only) with Benettin's tangent: the largest Lyapunov exponent of Lorenz-63
  against a published value."""

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxchain as jc
from jaxchain._engine import compat as _compat
from jaxchain._engine.smoothed import integrate
from jaxchain._engine.solver.controller import CONTROLLERS, PIController

def test_the_installed_diffrax_and_equinox_match():
    _compat.check_compatible()


def test_a_changed_private_part_is_named(monkeypatch):
    monkeypatch.delattr(diffrax.PIDController, "_get_error_order")
    with pytest.raises(RuntimeError, match="_get_error_order is gone.*diffrax"):
        _compat.check_compatible()


def test_a_changed_controller_state_is_named(monkeypatch):
    """As if diffrax's controller carried a fourth part in its state."""
    init = diffrax.PIDController.init

    def init_with_four_parts(self, *args):
        t1, state = init(self, *args)
        return t1, (*state, state[0])

    monkeypatch.setattr(diffrax.PIDController, "init", init_with_four_parts)
    with pytest.raises(RuntimeError, match="three parts"):
        _compat.check_compatible()


def test_errors_as_nan_is_undone_on_exit():
    before = eqx._errors.EQX_ON_ERROR
    with _compat.errors_as_nan():
        assert eqx._errors.EQX_ON_ERROR == "nan"
    assert eqx._errors.EQX_ON_ERROR == before


#: What a failing check raises: equinox's error, or under `jax.jit` XLA's, which
#: carries its message.
RAISED = (eqx.EquinoxRuntimeError, jax.errors.JaxRuntimeError)


def _checked(x):
    return eqx.error_if(x, jnp.sum(x) > 100.0, "the sum is too large")


def test_a_check_traced_as_nan_raises_again_after_the_block():
    """A check traced inside `errors_as_nan` gives NaN there; the same check (same
    shapes, same message) traced after the block raises again, eagerly and under
    `jax.jit`, and one traced raising before the block gives NaN inside it."""
    big = jnp.full(3, 50.0)
    with pytest.raises(RAISED, match="too large"):
        jax.jit(_checked)(big)  # traced raising first
    with _compat.errors_as_nan():
        assert jnp.isnan(jax.jit(lambda x: _checked(x) + 0.0)(big)).all()
    with pytest.raises(RAISED, match="too large"):
        _checked(big)
    with pytest.raises(RAISED, match="too large"):
        jax.jit(lambda x: _checked(x) * 1.0)(big)


RTOL, ATOL = 1e-4, 1e-6


def _adapt(controller, state, dt, err, y=1.0):
    """One call of adapt_step_size on a scalar state y with a scaled error `err`."""
    y0 = jnp.array([y])
    y_error = jnp.array([err * (ATOL + RTOL * y)])
    return controller.adapt_step_size(0.0, dt, y0, y0, None, y_error, 3, state)


def _state(prev_err=1.0):
    return ((jnp.asarray(1.0 / prev_err), jnp.asarray(1.0), False), jnp.asarray(0.0),
            jnp.asarray(0.0))


@pytest.mark.numerics
def test_accepted_step_follows_the_pi_rule_and_may_shrink():
    c = PIController(rtol=RTOL, atol=ATOL)
    keep, t0, t1, _, state, _ = _adapt(c, _state(prev_err=0.5), 0.1, 0.95)
    expected = 0.1 * 0.9 * 0.95 ** (-(0.5 + 0.2) / 3) * 0.5 ** (0.2 / 3)
    assert bool(keep) and float(t0) == 0.1
    assert np.isclose(float(t1 - t0), expected, rtol=1e-12)
    assert float(t1 - t0) < 0.1  # diffrax's controller would keep 0.1
    _, _, t1_diffrax, _, _, _ = diffrax.PIDController(rtol=RTOL, atol=ATOL).adapt_step_size(
        0.0, 0.1, jnp.array([1.0]), jnp.array([1.0]), None,
        jnp.array([0.95 * (ATOL + RTOL)]), 3, (jnp.asarray(1.0), jnp.asarray(1.0), False))
    assert float(t1_diffrax) - 0.1 == pytest.approx(0.1)


@pytest.mark.numerics
def test_second_rejection_uses_the_observed_order():
    c = PIController(rtol=RTOL, atol=ATOL)
    keep, t0, t1, _, state, _ = _adapt(c, _state(), 0.05, 2.65)
    assert not bool(keep) and float(t0) == 0.0
    first = float(t1)  # the asymptotic order 3: 0.9 * 2.65^(-1/3)
    assert np.isclose(first, 0.05 * 0.9 * 2.65 ** (-1 / 3), rtol=1e-12)
    keep, t0, t1, _, state, _ = _adapt(c, state, first, 2.37)
    q = np.log(2.65 / 2.37) / np.log(0.05 / first)
    assert q < 0.5  # the error hardly fell: the order is clipped to min_order
    assert not bool(keep)
    factor = max(c.factormin, 0.9 * 2.37 ** (-1 / 0.5))  # clipped to [factormin, safety]
    assert np.isclose(float(t1), first * factor, rtol=1e-12)
    assert float(t1) < first * 0.9 * 2.37 ** (-1 / 3)  # smaller than order 3 would take
    # an accepted step clears the rejection memory
    keep, t0, t1, _, state, _ = _adapt(c, state, float(t1), 0.5)
    assert bool(keep) and float(state[1]) == 0.0 and float(state[2]) == 0.0


@pytest.mark.numerics
def test_rejection_with_a_nan_error_shrinks_by_factormin():
    c = PIController(rtol=RTOL, atol=ATOL)
    keep, _, t1, _, _, _ = _adapt(c, _state(), 0.1, np.nan)
    assert not bool(keep) and np.isclose(float(t1), 0.1 * c.factormin)


def test_the_controllers_named_are_those_the_options_take():
    """test_solvers.py runs each controller by its documented name: the same set."""
    assert set(CONTROLLERS) == {"pi", "diffrax"}


def lorenz(t, y, args):
    sigma, rho, beta = 10.0, 28.0, 8.0 / 3.0
    return jnp.stack([sigma * (y[1] - y[0]), y[0] * (rho - y[2]) - y[1],
                      y[0] * y[1] - beta * y[2]])


@jax.jit
def _lorenz_exponent(y0):
    """One jitted run for every start below: traced and compiled once."""
    options = jc.SimulationOptions(t_end=20000.0, transient=50.0, chunk_length=10.0,
                                   rtol=1e-8, atol=1e-8, sample_dt=10.0, max_steps=10**5)
    return integrate(diffrax.ODETerm(lorenz), diffrax.Tsit5(), y0, None, options,
                        (jc.LargestLyapunov(),))


@pytest.mark.numerics
@pytest.mark.parametrize("shift", [0.0, 1e-3, -2e-3])
def test_lorenz_largest_exponent_is_0_9056_within_its_stated_error(shift):
    """Lorenz-63 at sigma = 10, rho = 28, beta = 8/3: 0.9056 (Sprott, Chaos and Time
    Series Analysis, 2003), by `jc.LargestLyapunov` on the smoothed engine's
    integrator. The start is perturbed: the trajectory is chaotic, so
    each start (and each CPU) gives another finite-time estimate."""
    (res,), _, _, status = _lorenz_exponent(jnp.array([1.0 + shift, 1.0, 1.0]))
    assert status == jc.Status.ok
    error = float(res["lyapunov_error"])
    assert 0 < error < 0.03
    assert abs(float(res["lyapunov"]) - 0.9056) < error
    history = np.asarray(res["lyapunov_history"])
    assert abs(history[-1] - float(res["lyapunov"])) < 1e-12  # the running estimate ends there
