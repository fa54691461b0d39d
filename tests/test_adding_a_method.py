"""A new orbit method is one class: the normal modes of the frictionless, undamped
linear chain, x'' = -M^-1 K x, whose periodic orbits are known in closed form, run
through `periodic_orbit` and `continuation` without touching another module
(docs/adding-a-method.md)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxchain as jc


# --8<-- [start:method]
class LinearNormalMode(jc.AbstractOrbitMethod):
    """The orbit of the linear chain x'' = -M^-1 K x (no friction, no damping) in its
    normal mode `mode` with the amplitude `amplitude` of its largest oscillator (oscillator 0 moving
    towards +):
    x(t) = a phi cos(omega t), T = 2 pi / omega. Unknowns u = (y0, T); the residual
    is u minus the closed form, so Newton's method lands on it in one step."""

    mode: int
    amplitude: float
    newton_tol: float = 1e-12
    newton_steps: int = 4

    def _mode(self, params):
        m = jnp.broadcast_to(params.mass if params.mass is not None else 1.0,
                             (params.n_osc,))
        k = jc.stiffness_matrix(params)
        scale = 1 / jnp.sqrt(m)  # M^-1/2 K M^-1/2 is symmetric
        omega2, shapes = jnp.linalg.eigh(scale[:, None] * k * scale[None, :])
        phi = scale * shapes[:, self.mode]
        # largest |phi_n| 1, phi_0 > 0 (an eigenvector's sign is arbitrary)
        phi = phi * jnp.sign(phi[0]) / jnp.max(jnp.abs(phi))
        return jnp.sqrt(omega2[self.mode]), phi

    def unknowns(self, params, y0, period):
        return self.pack(jnp.asarray(y0, dtype=float), period)

    def pack(self, y0, period):
        return jnp.concatenate([jnp.ravel(y0), jnp.atleast_1d(period)])

    def orbit(self, u):
        return jnp.reshape(u[:-1], (2, -1)), u[-1]

    def residual(self, u, params):
        omega, phi = self._mode(params)
        exact = self.pack(jnp.stack([self.amplitude * phi, jnp.zeros_like(phi)]),
                          2 * jnp.pi / omega)
        return u - exact

    def samples(self, params, u, ts):
        omega, phi = self._mode(params)
        wt = omega * jnp.asarray(ts)[:, None]
        return self.amplitude * jnp.stack([phi[None] * jnp.cos(wt),
                                           -omega * phi[None] * jnp.sin(wt)], axis=1)

    def _monodromy(self, params, y0, period):
        """exp(A T) of the first-order system y' = A y, and the flow direction A y0."""
        n = params.n_osc
        m = jnp.broadcast_to(params.mass if params.mass is not None else 1.0, (n,))
        a = jnp.block([[jnp.zeros((n, n)), jnp.eye(n)],
                       [-jc.stiffness_matrix(params) / m[:, None], jnp.zeros((n, n))]])
        return jax.scipy.linalg.expm(a * period), a @ jnp.ravel(y0)

    def multipliers(self, params, u):
        return jc.deflated_multipliers(*self._monodromy(params, *self.orbit(u)))

    def describe(self, u, params):
        y0, period = self.orbit(u)
        ys = self.samples(params, u, period * jnp.linspace(0.0, 1.0, 257)[1:])
        monodromy, direction = self._monodromy(params, y0, period)
        residual = jnp.max(jnp.abs(self.residual(u, params)))
        return jc.orbit_record(
            params, y0, period, ys, on_halc=jnp.zeros(params.n_osc, bool), m=monodromy,
            direction=direction, rtol=1e-14, log_det=jnp.asarray(0.0), residual=residual,
            converged=residual <= 1e3 * self.newton_tol)
# --8<-- [end:method]


def ring_period(n_osc, eta_c, mode):
    """The closed form on the homogeneous ring of unit masses and stiffnesses: mode j
    of the coupling has omega^2 = 1 + 4 eta_c sin^2(pi j / N) (eq. (5))."""
    omega2 = np.sort(1 + 4 * eta_c * np.sin(np.pi * np.arange(n_osc) / n_osc) ** 2)
    return 2 * np.pi / np.sqrt(omega2[mode])


def test_a_new_method_runs_through_periodic_orbit():
    params = jc.ChainParams(n_osc=5, eta_c=0.3)
    method = LinearNormalMode(mode=0, amplitude=0.7)
    orbit = jc.periodic_orbit(params, (jnp.zeros((2, 5)), 5.0), method)
    assert bool(orbit.converged)
    assert float(orbit.period) == pytest.approx(ring_period(5, 0.3, 0), rel=1e-12)
    # in phase: every oscillator at the amplitude
    np.testing.assert_allclose(orbit.amplitudes, 0.7, rtol=1e-4)
    # undamped and linear: every multiplier on the unit circle (closed form
    # exp(+- i omega_j T)), so the orbit is not asymptotically stable
    np.testing.assert_allclose(np.abs(orbit.multipliers), 1.0, atol=1e-9)
    assert not bool(orbit.stable)
    # the flow samples close the orbit: y(T) = y(0)
    back = method.samples(params, method.pack(orbit.y0, orbit.period),
                          jnp.array([float(orbit.period)]))[0]
    np.testing.assert_allclose(back, orbit.y0, atol=1e-12)


@pytest.mark.study
def test_a_new_method_runs_through_continuation():
    params = jc.ChainParams(n_osc=4, eta_c=0.1)
    method = LinearNormalMode(mode=3, amplitude=0.5)  # the anti-phase mode of the ring
    orbit = jc.periodic_orbit(params, (jnp.zeros((2, 4)), 5.0), method)
    branch = jc.continuation(jc.cycle_problem(orbit, method, where="eta_c"),
                             options=jc.ContinuationOptions(ds=0.1, ds_max=0.2, p_max=0.6,
                                                            max_points=12))
    ok = np.asarray(branch.converged)
    eta = np.asarray(branch.p)[ok]
    assert eta.max() > 0.5
    periods = np.asarray(branch.u)[ok][:, -1]
    np.testing.assert_allclose(periods, [ring_period(4, e, 3) for e in eta], rtol=1e-9)
