"""The solver of the smoothed engine: ROS34PW2 with a diagonal W (its order, and its
limit as eps -> 0), and its solutions under each step-size controller against scipy
and against each other.

ROS34PW2 is public (`jc.SOLVERS["ros34pw2"]`, a diffrax solver), and the split of
eq. (5) it integrates is written here. The controller's rules one call at a time and
the integrator on a system that is no chain have no public route: they are in
test_engine_internals.py."""

import dataclasses

import diffrax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp

import jaxchain as jc
from helpers import SHORT, flat, reference_rhs, scipy_stick_slip_cycle

#: ROS34PW2 (Rang & Angermann 2005), the smoothed engine's default solver.
Ros34PW2 = jc.SOLVERS["ros34pw2"]

#: The step-size controllers that `SimulationOptions.controller` names (its docstring).
CONTROLLERS = ("pi", "diffrax")


def _fixed_steps(split, y0, t1, n_steps, args=None, most=640):
    """`n_steps` steps of ROS34PW2 over [0, t1]. The step is an array and the step
    budget `most` + 1 for every count, so that every count runs one compiled program
    (a Python float or int is static: each would compile its own)."""
    assert n_steps <= most
    return diffrax.diffeqsolve(split, Ros34PW2(), 0.0, t1, jnp.asarray(t1 / n_steps), y0,
                               args, stepsize_controller=diffrax.ConstantStepSize(),
                               max_steps=most + 1)


def _fixed_step_error(split, y0, t1, exact, n_steps):
    sol = _fixed_steps(split, y0, t1, n_steps)
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
    p = jc.ChainParams(n_osc=4)
    engine = jc.Smoothed(eps=0.2)
    y0 = jc.OutOfPhaseExcitation.eq8(jc.excited_block(4, 2))(p)
    ref = diffrax.diffeqsolve(diffrax.ODETerm(lambda t, y, a: engine.field(p, y)),
                              diffrax.Dopri8(), 0.0, 4.0, None, y0, max_steps=None,
                              stepsize_controller=diffrax.PIDController(rtol=1e-13,
                                                                         atol=1e-15))

    def friction(t, y, a):
        """The stiff part, as the engine splits eq. (5): (0, F(x' - v_d)) with the
        smoothed force of eq. (1), -mu(|v_rel|) tanh(v_rel/eps), written here."""
        law, v_rel = p.friction, y[1] - p.v_d
        mu = law.mu_d + (law.mu_st - law.mu_d) * jnp.exp(-jnp.abs(v_rel) / law.v0)
        return jnp.stack([jnp.zeros_like(v_rel), -mu * jnp.tanh(v_rel / engine.eps)])

    split = diffrax.MultiTerm(
        diffrax.ODETerm(lambda t, y, a: engine.field(p, y) - friction(t, y, a)),
        diffrax.ODETerm(friction))
    errors = []
    for n in (80, 160, 320, 640):
        sol = _fixed_steps(split, y0, 4.0, n)
        errors.append(float(jnp.max(jnp.abs(sol.ys[-1] - ref.ys[-1]))))
    assert np.all(np.abs(_orders(errors) - 3) < 0.3), (errors, _orders(errors))


def _short(rtol, atol):
    """`SHORT` with the tolerances as arrays (traced: one program for any values)."""
    return dataclasses.replace(SHORT, rtol=jnp.asarray(rtol), atol=jnp.asarray(atol))


#: The smoothed engine's tolerances at the default eps (SimulationOptions leaves
#: them None, following eps).
DEFAULT_RTOL, DEFAULT_ATOL = jc.Smoothed().options.rtol, jc.Smoothed().options.atol

@pytest.mark.numerics
def test_converges_to_the_nonsmooth_stick_slip_cycle_as_eps_shrinks():
    """One oscillator at v_d = 1.5: the amplitude error against the non-smooth
    stick-slip cycle (scipy, with events) shrinks with eps down to 1e-5, where an
    explicit solver would be stiffness-bound, and the cycle sticks at every eps.
    The velocity error allowed per step, about rtol v_d, must stay below the width
    eps of the stick band, so rtol is at most eps / 10 (the default 1e-5 down to
    eps = 1e-4). The tolerances are arrays: one compiled program for every eps."""
    reference = scipy_stick_slip_cycle(jc.ChainParams(n_osc=1))[0]
    errors = []
    p = jc.ChainParams(n_osc=1)
    for eps in (1e-2, 1e-3, 1e-4, 1e-5):
        rtol = min(DEFAULT_RTOL, eps / 10)
        options = _short(rtol, rtol / 100)
        obs = jc.simulate(p, jc.OutOfPhaseExcitation.eq8([True]),
                          engine=jc.Smoothed("ros34pw2", options, eps))
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
    p, eps = jc.ChainParams(n_osc=1), 1e-5
    ic = jc.OutOfPhaseExcitation.eq8([True])
    options = _short(DEFAULT_RTOL, DEFAULT_ATOL)  # ROS34PW2's program of the test above
    rosw = jc.simulate(p, ic, engine=jc.Smoothed("ros34pw2", options, eps))
    bosh = jc.simulate(p, ic, engine=jc.Smoothed(diffrax.Bosh3(), options, eps),
                       throw=False)
    assert int(rosw.n_halc) == 1
    assert (bosh.status == jc.Status.max_steps_reached
            or int(bosh.num_steps) > 10 * int(rosw.num_steps))


@pytest.mark.numerics
@pytest.mark.parametrize("controller", CONTROLLERS)
def test_solution_matches_scipy_within_the_tolerance(controller):
    """Three oscillators through stick-slip switches, t in [0, 60]: the final state
    against scipy's DOP853 at rtol 1e-12, within a bound set by rtol = 1e-7 (the
    global error of 60 time units with some 20 switches, a few hundred times the
    local tolerance)."""
    p = jc.ChainParams(n_osc=3, v_d=1.5)
    y0 = jc.OutOfPhaseExcitation.eq8(np.array([True, False, True]))(p)
    opts = jc.SimulationOptions(t_end=60.0, transient=0.0, rtol=1e-7, atol=1e-9,
                                controller=controller)
    obs = jc.simulate(p, y0, options=opts)
    ref = solve_ivp(reference_rhs(p), (0.0, 60.0), np.asarray(flat(y0)), method="DOP853",
                    rtol=1e-12, atol=1e-13)
    assert obs.status == jc.Status.ok
    assert np.allclose(flat(obs.y_final), ref.y[:, -1], atol=1e-7 * 1e3)


@pytest.mark.numerics
@pytest.mark.study
def test_both_controllers_give_the_same_localized_state():
    """The default controller and diffrax's, at the default tolerances: the same
    oscillators on the HALC and amplitudes within the cross-check's 1 %."""
    p = jc.ChainParams(n_osc=8, v_d=1.5)
    y0 = jc.OutOfPhaseExcitation.eq8(jc.excited_block(8, 2))(p)
    runs = [jc.simulate(p, y0, options=jc.SimulationOptions(
        t_end=600.0, transient=400.0, controller=c)) for c in ("pi", "diffrax")]
    assert int(runs[0].n_halc) == int(runs[1].n_halc) == 2
    assert np.allclose(runs[0].amplitudes, runs[1].amplitudes, rtol=1e-2,
                       atol=1e-2 * float(np.max(runs[1].amplitudes)))
