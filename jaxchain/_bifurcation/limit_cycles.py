"""The limit-cycle branch born at the Hopf point of steady sliding: its first small
cycle, and its continuation problem."""

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._physics.forces import DEFAULT_EPS
from .._physics.model import steady_sliding
from .._physics.params import ChainParams, with_parameter
from .continuation import ContinuationProblem
from .hopf import check_eps, critical_mode, hopf_point
from .lyapunov_coefficient import first_lyapunov_coefficient
from .shooting import (DescribeOrbit, PeriodicOrbit, ShootingOptions, pack,
                       periodic_orbit, shooting_residual)
from .._checks import check_positive
from .._errors import ValidationError


class ShootingResidual(eqx.Module):
    """`shooting_residual` with its options and smoothing velocity bound, as a
    `ContinuationProblem` residual: equal options give equal residuals, so
    continuation compiles once (eps is an array leaf: a new eps does not
    recompile, and derivatives with respect to it flow).

    **Fields:** `options` (`ShootingOptions`); `eps`, the smoothing velocity of
    tanh(v_rel/eps) (> 0), shape (), dimensionless (`DEFAULT_EPS` by default)."""

    options: ShootingOptions
    eps: Float[Array, ""] = eqx.field(converter=check_eps, default=DEFAULT_EPS)

    def __call__(self, u, params):
        return shooting_residual(u, params, self.options, self.eps)


def problem_eps(problem: ContinuationProblem) -> Float[Array, ""]:
    """The smoothing velocity of the limit cycles that `problem` continues: the eps
    of its `ShootingResidual` (`limit_cycle_problem`), or of the problem whose
    folds a `FoldSystem` residual follows.

    **Raises:**

    `ValidationError` for a problem whose residual carries no eps (give eps
    explicitly)."""
    residual = problem.residual
    while not isinstance(residual, ShootingResidual) and hasattr(residual, "problem"):
        residual = residual.problem.residual
    if not isinstance(residual, ShootingResidual):
        raise ValidationError("eps: the problem is not one of limit cycles "
                              "(limit_cycle_problem), whose shooting carries eps; give eps")
    return residual.eps


def limit_cycle_problem(orbit: PeriodicOrbit, options: ShootingOptions = ShootingOptions(),
                        where="v_d") -> ContinuationProblem:
    """The `ContinuationProblem` of the periodic orbits through `orbit`: unknowns
    (y0, T) of `shooting_residual`, records `describe_orbit` (amplitudes, energy,
    Floquet multipliers, stability), at the orbit's smoothing velocity `orbit.eps`.

    **Arguments:**

    - `orbit`: a converged `PeriodicOrbit`.
    - `options`: `ShootingOptions` of every point.
    - `where`: the continued parameter, a name or a lens (default the belt speed).
    """
    return ContinuationProblem(
        residual=ShootingResidual(options, orbit.eps), u0=pack(orbit.y0, orbit.period),
        params=orbit.params, where=where, describe=DescribeOrbit(options, orbit.eps))


def hopf_cycle(params: ChainParams, offset: float = 1e-3, mode: int = 0,
               options: ShootingOptions = ShootingOptions(), *,
               eps=DEFAULT_EPS) -> PeriodicOrbit:
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
    - `options`: `ShootingOptions`.
    - `eps`: the smoothing velocity of tanh(v_rel/eps) in eq. (5), a finite number
        > 0, shape (), dimensionless (a fraction of x_0 omega_n): that of the
        Hopf point, the normal form and the orbit (`Smoothed.eps` of the smoothed
        engine), `DEFAULT_EPS` by default.

    **Returns:**

    A `PeriodicOrbit` at v_d = v_d,H +- offset.

    **Raises:**

    `ValidationError` for offset <= 0, eps <= 0 or a bad mode; `RuntimeError` if
    shooting fails.
    """
    check_positive("offset", offset)
    hopf = hopf_point(params, eps=eps)
    at_hopf = with_parameter(params, "v_d", hopf.v_d[mode])
    l1 = first_lyapunov_coefficient(at_hopf, mode, eps=eps)
    v_d = hopf.v_d[mode] + jnp.sign(l1) * offset
    near = with_parameter(params, "v_d", v_d)
    n = params.n_osc
    _, q, _ = critical_mode(at_hopf, mode, eps)
    growth = hopf.slope[mode] * (v_d - hopf.v_d[mode])
    radius = jnp.sqrt(-growth / (l1 * hopf.omega[mode]))
    q = q * jnp.exp(1j * (np.pi / 2 - jnp.angle(q[n])))  # x_1' = 0 at the start
    y0 = steady_sliding(near, eps) + jnp.reshape(2 * radius * q.real, (2, n))
    return periodic_orbit(near, y0, float(2 * np.pi / hopf.omega[mode]), options, eps=eps)
