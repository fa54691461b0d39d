"""The limit-cycle branch born at the Hopf point of steady sliding: its first small
cycle."""

import jax.numpy as jnp
import numpy as np

from .._physics.params import ChainParams, with_parameter
from .hopf import critical_mode, hopf_point
from .lyapunov_coefficient import first_lyapunov_coefficient
from .orbit_method import PeriodicOrbit
from .periodic_orbit import periodic_orbit
from .shooting import Shooting
from .._checks import check_positive


def hopf_cycle(params: ChainParams, offset: float = 1e-3, mode: int = 0,
               method: Shooting | None = None) -> PeriodicOrbit:
    """The small limit cycle born at the Hopf point of steady sliding in the critical
    mode `mode` (`critical_mode`; 0: in phase on the ring), a distance `offset` in
    v_d from the Hopf point on the side where the first Lyapunov coefficient puts
    it (above v_d,H when subcritical).

    The guess is the normal form of the Hopf bifurcation (Kuznetsov, *Elements of
    Applied Bifurcation Theory*, Sect. 3.5): y = y_ss + 2 Re(z q) with |z|^2 =
    -Re(lambda)(v_d) / (l1 omega) and q the critical eigenvector; shooting then
    solves for the cycle.

    **Arguments:**

    - `params`: the chain parameters; `params.v_d` is ignored.
    - `offset`: |v_d - v_d,H| of the cycle, > 0.
    - `mode`: Fourier mode with a real mode shape, 0 or N/2, on the homogeneous
        ring; 0 (the leading eigenvalue) on any other chain.
    - `method`: the orbit method (`Shooting()` by default); the Hopf point and
        the normal form are those of its engine's smoothed vector field (its
        `Smoothed.eps`).

    **Returns:**

    A `PeriodicOrbit` at v_d = v_d,H +- offset.

    **Raises:**

    `ValidationError` for offset <= 0, a bad mode or an engine that does not
    smooth (the normal form needs the smoothed vector field); `RuntimeError` if
    shooting fails.
    """
    check_positive("offset", offset)
    method = Shooting() if method is None else method
    smoothed = method.engine.as_smoothed("hopf_cycle")
    hopf = hopf_point(params, engine=smoothed)
    at_hopf = with_parameter(params, "v_d", hopf.v_d[mode])
    l1 = first_lyapunov_coefficient(at_hopf, mode, engine=smoothed)
    v_d = hopf.v_d[mode] + jnp.sign(l1) * offset
    near = with_parameter(params, "v_d", v_d)
    n = params.n_osc
    _, q, _ = critical_mode(at_hopf, mode, smoothed)
    growth = hopf.slope[mode] * (v_d - hopf.v_d[mode])
    radius = jnp.sqrt(-growth / (l1 * hopf.omega[mode]))
    q = q * jnp.exp(1j * (np.pi / 2 - jnp.angle(q[n])))  # x_1' = 0 at the start
    y0 = method.engine.steady_sliding(near) + jnp.reshape(2 * radius * q.real, (2, n))
    return periodic_orbit(near, (y0, float(2 * np.pi / hopf.omega[mode])), method)
