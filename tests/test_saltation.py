"""Derivatives of the exact engine through its switches (issue 55, item 3): the
saltation matrix of each kind of switch against finite differences of the flow
across it, and the gradients of a chain of four through many switches against
finite differences of the engine itself, in forward and in reverse mode."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp

import jaxchain as jc

#: Two oscillators on a ring whose first switches are one of each kind
#: (`jc.SWITCH_KINDS`): oscillator 1 sticks at t = 0.633 and breaks away at 1.628,
#: oscillator 0 reverses its slip at 3.906 (|f| > mu_st there).
PAIR = jc.ChainParams(n_osc=2, v_d=1.0)
PAIR_Y0 = np.array([[3.0, -0.5], [1.0, 0.3]])
REFERENCE = jc.NonsmoothOptions.reference(t_end=8.0, transient=0.0, log_size=32)


def _slip_force(params, v_rel, modes):
    """The friction force of eq. (2) in slip of direction s = `modes` (+1 or -1),
    -(P_n/P) mu(s v_rel) s, with the law's mu of the slip speed
    (`AbstractFrictionLaw.of_slip_speed`): the sign is the mode's, not that of
    v_rel, so that the force stays smooth within a phase, as the exact engine
    holds it."""
    return -(params.load * params.friction.of_slip_speed(modes * v_rel)) * modes


def _field(params, y, modes):
    """The chain's vector field with fixed modes, written here from the public force
    functions: stick x' = v_d, x'' = 0; slip x'' = -f(x) - 2 xi (x' - v_d) +
    F_slip, with f the force needed to stick (`jc.stick_force`, eq. (5))."""
    x, v = y[0], y[1]
    a = (-jc.stick_force(params, x) - 2 * params.xi * (v - params.v_d)
         + _slip_force(params, v - params.v_d, modes))
    stick = modes == 0
    return jnp.stack([jnp.where(stick, params.v_d, v), jnp.where(stick, 0.0, a)])


def _smooth_flow(params, y, modes, duration):
    """The state and its Jacobian (the fundamental matrix) after `duration` in fixed
    modes: the variational equations Phi' = A(y) Phi beside the state, scipy's
    DOP853 at rtol 1e-12, A by JAX from `_field`. Shapes (2, n) and (2n, 2n)."""
    n = y.size

    def f(y_flat):
        return _field(params, y_flat.reshape(2, -1), modes).reshape(-1)

    jac = jax.jit(jax.jacfwd(f))
    f = jax.jit(f)

    def rhs(_, z):
        y_flat, phi = z[:n], z[n:].reshape(n, n)
        return np.concatenate([np.asarray(f(y_flat)), (np.asarray(jac(y_flat)) @ phi).ravel()])

    z0 = np.concatenate([np.ravel(y), np.eye(n).ravel()])
    sol = solve_ivp(rhs, (0.0, duration), z0, method="DOP853", rtol=1e-12, atol=1e-12)
    return sol.y[:n, -1].reshape(2, -1), sol.y[n:, -1].reshape(n, n)


def _modes(params, y):
    """Modes of a state of the exact engine: stick where x' = v_d exactly (as the
    engine leaves a sticking oscillator), else the sign of x' - v_d."""
    v_rel = np.asarray(y[1]) - float(params.v_d)
    return np.where(v_rel == 0, 0.0, np.sign(v_rel))


def _first_switch(kind):
    """Time and oscillator of the pair's first switch of `kind`."""
    obs = jc.simulate(PAIR, PAIR_Y0, engine=jc.Exact(REFERENCE))
    (i,) = np.flatnonzero(np.asarray(obs.log_kind) == kind)[:1]
    return float(obs.log_time[i]), int(obs.log_osc[i])


@pytest.mark.study
@pytest.mark.numerics
@pytest.mark.parametrize("kind", [0, 1, 2], ids=list(jc.SWITCH_KINDS))
def test_saltation_matrix_is_the_flow_s_jump_across_each_kind_of_switch(kind):
    """Across a switch at t* the Jacobian of the flow from t* - d to t* + d is
    Phi+ S Phi-: the smooth flows of the modes before and after (`_smooth_flow`,
    scipy) and the saltation matrix S (`jc.saltation_matrix`, Leine and Nijmeijer
    2004). It is checked against central differences of the exact engine's flow
    (h = 1e-6 at rtol 1e-12: error ~1e-12/h + h^2 ~ 1e-6) and against the
    engine's own forward-mode Jacobian. Directions that leave the switch surface
    of a sticking oscillator (its x' = v_d exactly) are not perturbed: a
    perturbed stuck velocity is a slipping oscillator."""
    t_switch, osc = _first_switch(kind)
    d = 0.05
    (y_a,) = np.asarray(jc.Exact(REFERENCE).flow(PAIR, PAIR_Y0, jnp.array([t_switch - d])))
    before = _modes(PAIR, y_a)
    y_star, phi_before = _smooth_flow(PAIR, y_a, before, d)
    after = before.copy()
    f = float(jc.stick_force(PAIR, jnp.asarray(y_star[0]))[osc])
    after[osc] = {0: -np.sign(f), 1: 0.0, 2: -before[osc]}[kind]
    salt = np.asarray(jc.saltation_matrix(PAIR, jnp.asarray(y_star), jnp.asarray(before),
                                          jnp.asarray(after), osc))
    y_plus = y_star.copy()
    y_plus[1, osc] = float(PAIR.v_d)  # the switch sets x' = v_d (a change ~ rtol)
    _, phi_after = _smooth_flow(PAIR, y_plus, after, d)
    expected = phi_after @ salt @ phi_before

    def flow(y):
        ys = jc.Exact(REFERENCE).flow(PAIR, y, jnp.array([2 * d]))
        return ys[0].reshape(-1)

    free = np.ones(4, bool)
    free[2:] = before != 0  # the velocities of slipping oscillators only
    h = 1e-6
    columns = [np.asarray(flow(jnp.asarray(y_a + h * e)) - flow(jnp.asarray(y_a - h * e))) / (2 * h)
               for e in np.eye(4).reshape(4, 2, 2)[free]]
    np.testing.assert_allclose(np.stack(columns, 1), expected[:, free], atol=2e-5)
    forward = np.asarray(jax.jacfwd(flow)(jnp.asarray(y_a))).reshape(4, 4)
    # A reversal's step straddles the kink of mu(|v_rel|) at v_rel = 0 (the slip
    # law is mirrored past the end of a phase, which keeps a phase that begins
    # tangentially from chattering): its derivative is as accurate as that step,
    # 5e-7 here, and is checked to the differences' accuracy.
    np.testing.assert_allclose(forward[:, free], expected[:, free],
                               atol=2e-5 if kind == 2 else 1e-9)
    if kind == 1:  # slip to stick: the velocity's perturbation is lost
        np.testing.assert_allclose(salt, np.eye(4) - np.diag(np.eye(4)[2 + osc]), atol=1e-9)
    if kind == 2:  # slip reversal: the acceleration jumps by 2 mu_st
        assert np.abs(salt - np.eye(4)).max() > 0.1


#: A ring of four from a state whose first 17 switches on [0, 12] are of every kind
#: on every oscillator (two slip reversals of oscillator 0 among them), none
#: within 0.02 of another or of t = 12.
RING4_Y0 = np.array([[3.0, -0.5, 0.3, -1.0], [1.3, 0.2, 1.5, -0.4]])
WEIGHTS = np.array([[1.0, -0.7, 0.4, 0.2], [0.3, 0.5, -0.9, 0.6]])


def _weighted_final_state(v_d, xi, y0, options):
    """sum(WEIGHTS * y(12)) on the ring of four, by the exact engine."""
    params = jc.ChainParams(n_osc=4, v_d=v_d, xi=xi)
    ys = jc.Exact(options).flow(params, y0, jnp.array([12.0]))
    return jnp.sum(WEIGHTS * ys[0])


@pytest.mark.study
@pytest.mark.numerics
@pytest.mark.parametrize("adjoint", ["forward", "reverse"])
def test_chain_of_four_gradients_through_every_switch_are_finite_differences(adjoint):
    """The gradient of a weighted final state of a ring of four in v_d, xi and the
    eight initial coordinates, through 17 switches of every kind: forward mode
    (`jax.jacfwd`) and reverse mode (`jax.grad`, nested checkpointed loops), under
    `jax.jit`, against central differences of the exact engine at rtol 1e-12 (h =
    1e-6: noise
    ~1e-12/h = 1e-6 of the value, truncation ~h^2; hence 1e-5 of the largest
    derivative)."""
    options = jc.NonsmoothOptions.reference(t_end=12.0, transient=0.0, adjoint=adjoint)
    inputs = (1.2, 0.05, jnp.asarray(RING4_Y0))
    # Under jax.jit, with jaxchain's XLA flags (`configure`), as a user's gradient
    # step runs it: reverse mode through equinox's checkpointed loop was wrong
    # there by 0.04 (XLA's small-while-loop kernels), and right without the jit.
    differentiate = jax.grad if adjoint == "reverse" else jax.jacfwd
    got = jax.jit(differentiate(_weighted_final_state, argnums=(0, 1, 2)),
                  static_argnums=3)(*inputs, options)
    got = np.concatenate([np.ravel(g) for g in got])
    reference = jc.NonsmoothOptions.reference(t_end=12.0, transient=0.0)
    value = jax.jit(_weighted_final_state, static_argnums=3)
    h = 1e-6
    fd = []
    for k in range(10):
        def shifted(step):
            v_d, xi, y0 = inputs
            if k == 0:
                v_d = v_d + step
            elif k == 1:
                xi = xi + step
            else:
                y0 = y0.at[(k - 2) // 4, (k - 2) % 4].add(step)
            return float(value(v_d, xi, y0, reference))
        fd.append((shifted(h) - shifted(-h)) / (2 * h))
    np.testing.assert_allclose(got, fd, rtol=0, atol=1e-5 * np.abs(fd).max())
    assert np.abs(fd).max() > 0.1  # derivatives that could be wrong
