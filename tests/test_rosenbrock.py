"""ROS34PW2 with a diagonal W: its order, and its limit as eps -> 0."""

import dataclasses

import diffrax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxchain as jc
from helpers import SHORT, scipy_stick_slip_cycle
from jaxchain._engine.solver.rosenbrock import Ros34PW2
from jaxchain._engine.simulate import terms


def _fixed_step_error(split, y0, t1, exact, n_steps):
    sol = diffrax.diffeqsolve(split, Ros34PW2(), 0.0, t1, t1 / n_steps, y0,
                              stepsize_controller=diffrax.ConstantStepSize(),
                              max_steps=n_steps + 1)
    return float(jnp.max(jnp.abs(sol.ys[-1] - exact)))


def _orders(errors):
    return np.log2(np.asarray(errors[:-1]) / np.asarray(errors[1:]))


@pytest.mark.numerics
def test_order_three_on_a_linear_problem_whose_w_is_not_its_jacobian():
    """y' = R y - lam y, a rotation (explicit) plus a diagonal decay (the stiff term),
    has the exact solution exp(-lam t) R(t) y0. W holds only the decay, not the
    rotation, so the method runs as a W-method; it still converges with order 3."""
    lam = 2.0
    split = diffrax.MultiTerm(
        diffrax.ODETerm(lambda t, y, a: jnp.stack([y[1], -y[0]])),
        diffrax.ODETerm(lambda t, y, a: -lam * y))
    y0, t1 = jnp.array([1.0, 0.5]), 3.0
    c, s = np.cos(t1), np.sin(t1)
    exact = np.exp(-lam * t1) * np.array([c * y0[0] + s * y0[1], -s * y0[0] + c * y0[1]])
    errors = [_fixed_step_error(split, y0, t1, exact, n) for n in (40, 80, 160, 320)]
    assert np.all(np.abs(_orders(errors) - 3) < 0.15), (errors, _orders(errors))


@pytest.mark.numerics
def test_order_three_on_the_smooth_chain_against_dopri8():
    """Eq. (5) with a wide smoothing (eps = 0.2, no sharp stick) from an excited
    state, over t in [0, 4]: the fixed-step error against Dopri8 at rtol 1e-13
    falls with order 3 (the friction Jacobian is nonlinear, W is frozen per step)."""
    p = jc.ChainParams(n_osc=4, eps=0.2)
    y0 = jc.OutOfPhaseExcitation.eq8(jc.excited_block(4, 2))(p)
    ref = diffrax.diffeqsolve(diffrax.ODETerm(jc.vector_field), diffrax.Dopri8(), 0.0, 4.0,
                              None, y0, p, max_steps=None,
                              stepsize_controller=diffrax.PIDController(rtol=1e-13,
                                                                         atol=1e-15))
    split = terms(Ros34PW2())
    errors = []
    for n in (80, 160, 320, 640):
        sol = diffrax.diffeqsolve(split, Ros34PW2(), 0.0, 4.0, 4.0 / n, y0, p,
                                  stepsize_controller=diffrax.ConstantStepSize(),
                                  max_steps=n + 1)
        errors.append(float(jnp.max(jnp.abs(sol.ys[-1] - ref.ys[-1]))))
    assert np.all(np.abs(_orders(errors) - 3) < 0.3), (errors, _orders(errors))


@pytest.mark.numerics
def test_converges_to_the_nonsmooth_stick_slip_cycle_as_eps_shrinks():
    """One oscillator at v_d = 1.5: the amplitude error against the non-smooth
    stick-slip cycle (scipy, with events) shrinks with eps down to 1e-5, where an
    explicit solver would be stiffness-bound, and the cycle sticks at every eps.
    The velocity error allowed per step, about rtol v_d, must stay below the width
    eps of the stick band, so rtol is at most eps / 10 (the default 1e-5 down to
    eps = 1e-4)."""
    reference = scipy_stick_slip_cycle(jc.ChainParams(n_osc=1))[0]
    errors = []
    for eps in (1e-2, 1e-3, 1e-4, 1e-5):
        p = jc.ChainParams(n_osc=1, eps=eps)
        rtol = min(SHORT.rtol, eps / 10)
        options = dataclasses.replace(SHORT, rtol=rtol, atol=rtol / 100)
        obs = jc.simulate(p, jc.OutOfPhaseExcitation.eq8([True]), Ros34PW2(), options)
        assert int(obs.n_halc) == 1
        errors.append(abs(float(obs.amplitudes[0]) / reference - 1))
    assert np.all(np.diff(errors) < 0), errors
    assert errors[-1] < 2e-4, errors


@pytest.mark.numerics
def test_steps_are_not_bound_by_stiffness():
    """At eps = 1e-5 the stick phase has stiffness mu_st / eps = 2e5. The explicit
    Bosh3 must keep its step below its stability limit, about 1e-5, through every
    stick phase; ROS34PW2 (L-stable) need not. With the same step budget (200000
    steps per chunk of 100 time units) Bosh3 either runs out of steps or takes over
    10 times as many."""
    p = jc.ChainParams(n_osc=1, eps=1e-5)
    ic = jc.OutOfPhaseExcitation.eq8([True])
    rosw = jc.simulate(p, ic, Ros34PW2(), SHORT)
    bosh = jc.simulate(p, ic, diffrax.Bosh3(), SHORT, throw=False)
    assert int(rosw.n_halc) == 1
    assert (bosh.status == jc.Status.max_steps_reached
            or int(bosh.num_steps) > 10 * int(rosw.num_steps))
