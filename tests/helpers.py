"""Small shared systems and references for the tests."""

import jax.numpy as jnp
import numpy as np

import jaxchain as jc

#: A short horizon that still reaches the stick-slip cycle of one oscillator.
SHORT = jc.SimulationOptions(t_end=600.0, transient=300.0, chunk_length=100.0)


def reference_rhs(params: jc.ChainParams):
    """Eq. (5) written out oscillator by oscillator with NumPy, independently of
    `jc.vector_field`, for scipy and for comparison."""
    n = params.n_osc

    def rhs(t, y):
        x, v = y[:n], y[n:]
        a = np.empty(n)
        for i in range(n):
            left, right = x[(i - 1) % n], x[(i + 1) % n]
            v_rel = v[i] - params.v_d
            mu = params.mu_d + (params.mu_st - params.mu_d) * np.exp(-abs(v_rel) / params.v0)
            force = -mu * np.tanh(v_rel / params.eps)
            a[i] = (-2 * params.xi * v[i] - x[i]
                    - params.eta_c * (2 * x[i] - left - right) + force)
        return np.concatenate([v, a])

    return rhs


def flat(y) -> jnp.ndarray:
    return jnp.reshape(jnp.asarray(y), (-1,))
