"""Periodic orbits of the exact stick/slip switch model by single shooting on the
exact engine, and their exact Floquet multipliers: the monodromy matrix is the
exact engine's derivative of its flow map, the product of the smooth flows'
Jacobians and the saltation matrix of every switch."""

import equinox as eqx
import jax
import jax.numpy as jnp
import optimistix as optx
from jaxtyping import Array, Bool, Complex, Float, Int

from .._engine.compat import checks_as_nan
from .._engine.exact.options import NonsmoothOptions
from .._engine.exact.solve import nonsmooth_flow
from .._engine.exact.switching import initial_modes, mode_field
from .._engine.status import Status
from .._errors import ValidationError
from .._physics.custom_types import State
from .._physics.params import ChainParams
from .continuation import ContinuationProblem, describe_point
from .shooting import (critical_multiplier, deflated_multipliers, multiplier_resolution,
                       pack, shooting_guess, unpack)
from .._printing import values_repr


class ExactShooting(eqx.Module):
    """How periodic orbits of the exact switch model are solved for.

    **Arguments:**

    - `flow`: `NonsmoothOptions` of the exact engine's flow over one period (its
        horizon is not read; forward-mode derivatives are needed, so `adjoint`
        must be "forward"). The reference's tolerances by default (Tsit5 at
        rtol = atol = 1e-12): the trivial multiplier is 1 only as far as the
        flow is exact.
    - `newton_tol`: Newton's tolerance (optimistix, rtol = atol) on the state and
        period.
    - `newton_steps`: Newton's iteration budget.
    - `damped_steps`: the iteration budget of the damped Newton method (Newton
        steps shortened by Armijo backtracking on the squared residual; Dennis and
        Schnabel 1996, Sect. 6.3) tried from the same guess where Newton's method
        fails: near an orbit with multipliers close to +1 (weakly coupled
        oscillators' phases), a full Newton step from a guess 0.05 away leaves
        the orbit's neighbourhood. 0 for none.
    - `n_samples`: samples of one period from which amplitudes and stick are
        read (an extremum between samples is missed by about
        A (pi / n_samples)^2 / 2).
    - `phase_oscillator`: the oscillator n of the phase condition x_n'(0) = 0
        (0-based): the orbit starts at a turning point of n, in slip; choose
        one that vibrates.

    **Raises:**

    `ValidationError` naming the field for a non-positive tolerance or count, a
    negative phase oscillator or a reverse-mode flow.
    """

    flow: NonsmoothOptions = NonsmoothOptions.reference(t_end=1.0, transient=0.0)
    newton_tol: float = eqx.field(static=True, default=1e-9)
    newton_steps: int = eqx.field(static=True, default=40)
    damped_steps: int = eqx.field(static=True, default=120)
    n_samples: int = eqx.field(static=True, default=4096)
    phase_oscillator: int = eqx.field(static=True, default=0)

    def __check_init__(self):
        if self.phase_oscillator < 0:
            raise ValidationError(f"ExactShooting.phase_oscillator must be >= 0, got "
                                  f"{self.phase_oscillator!r}")
        if self.flow.adjoint != "forward":
            raise ValidationError("ExactShooting.flow.adjoint must be 'forward': Newton's "
                                  "method and the monodromy matrix use forward mode")
        for name in ("newton_tol", "newton_steps", "n_samples"):
            if not getattr(self, name) > 0:
                raise ValidationError(f"ExactShooting.{name} must be > 0, got "
                                      f"{getattr(self, name)!r}")
        if not self.damped_steps >= 0:
            raise ValidationError(f"ExactShooting.damped_steps must be >= 0, got "
                                  f"{self.damped_steps!r}")


def exact_flow(params: ChainParams, y0: State, period, options: ExactShooting) -> State:
    """The exact engine's state after `period` from `y0`, shape (2, n_osc)
    (`nonsmooth_flow`); NaN where the run failed."""
    ys, status = nonsmooth_flow(params, y0, jnp.atleast_1d(period), options.flow)
    return jnp.where(status == Status.ok, ys[-1], jnp.nan)


def exact_shooting_residual(u: Float[Array, " 2n+1"], params: ChainParams,
                            options: ExactShooting) -> Float[Array, " 2n+1"]:
    """Single-shooting residual of a periodic orbit of the exact switch model
    (Seydel, *Practical Bifurcation and Stability Analysis*, 3rd ed. (2010),
    Sect. 7.1): the exact flow over one period minus the start, and the phase
    condition x_n'(0) = 0 (n = `options.phase_oscillator`). A sticking
    oscillator's velocity is v_d exactly at both ends, so its rows are zero on
    the orbit and its column of the monodromy matrix is zero.

    **Arguments:**

    - `u`: the unknowns `pack(y0, T)`, shape (2 n_osc + 1,).
    - `params`: the chain parameters.
    - `options`: `ExactShooting`.

    **Returns:**

    Shape (2 n_osc + 1,); zero on a periodic orbit.
    """
    y0, period = unpack(u)
    n = options.phase_oscillator
    return jnp.concatenate([jnp.reshape(exact_flow(params, y0, period, options) - y0, (-1,)),
                            y0[1, n:n + 1]])


def exact_monodromy(params: ChainParams, y0: State, period, options: ExactShooting
                    ) -> Float[Array, "2n 2n"]:
    """The monodromy matrix d phi_T(y0) / d y0 of the exact switch model: forward-mode
    differentiation of the exact engine's flow through every switch, which
    applies each switch's saltation matrix (`saltation_matrix`; Leine and
    Nijmeijer, *Dynamics and Bifurcations of Non-Smooth Mechanical Systems*,
    2004, Sect. 7.1). Ordered as (x_1..x_N, x_1'..x_N'), shape (2 n_osc, 2 n_osc)."""
    def end(z):
        return jnp.reshape(exact_flow(params, jnp.reshape(z, (2, -1)), period, options), (-1,))
    return jax.jacfwd(end)(jnp.reshape(y0, (-1,)))


def exact_floquet_multipliers(params: ChainParams, y0: State, period,
                              options: ExactShooting) -> tuple[Complex[Array, " 2n"], Array]:
    """The exact Floquet multipliers of the orbit through `y0` with period `period`:
    the eigenvalues of `exact_monodromy` by decreasing modulus, the trivial one (of
    the flow direction, the vector field at y0) deflated from the rest
    (`deflated_multipliers`). Returns (multipliers, shape (2 n_osc,); the index of
    the trivial one, shape ())."""
    return _deflated(params, y0, exact_monodromy(params, y0, period, options))


def _deflated(params: ChainParams, y0: State, m: Float[Array, "2n 2n"]
              ) -> tuple[Complex[Array, " 2n"], Array]:
    """The multipliers of the exact monodromy `m` of the orbit through `y0`, the
    trivial one (of the exact vector field at y0) deflated."""
    modes = initial_modes(params, y0)
    direction = jnp.reshape(mode_field(0.0, (y0, None), (params, modes))[0], (-1,))
    return deflated_multipliers(m, direction)


class ExactOrbit(eqx.Module):
    """A periodic orbit of the exact switch model and its exact stability.

    **Fields:**

    - `params`: the parameters it belongs to.
    - `y0`: the state at t = 0 (x_n'(0) = 0, n the phase oscillator), shape
        (2, n_osc).
    - `period`: T, shape ().
    - `amplitudes`: half of peak-to-peak of each x_n over `n_samples` samples of
        the period, shape (n_osc,).
    - `energy`: E = 1/2 sum_n A_n^2 (eq. (9) of the paper), shape ().
    - `on_halc`: whether each oscillator sticks during the period (x_n' = v_d
        exactly at a sample: the exact engine's stick), shape (n_osc,).
    - `n_halc`: the number of them, shape ().
    - `multipliers`: the Floquet multipliers by decreasing modulus, shape
        (2 n_osc,): the eigenvalues of the exact monodromy matrix. Each
        oscillator that sticks loses the perturbation of its velocity there, so
        stick phases give multipliers at zero (`zero_multipliers` of them).
    - `trivial`: index of the trivial multiplier (of the flow direction), shape ().
    - `zero_multipliers`: multipliers of modulus below 1e-9, shape ().
    - `resolved`: whether each multiplier lies above `multiplier_resolution` in
        modulus, shape (2 n_osc,): as `PeriodicOrbit.resolved`, for the error of
        the computed exact monodromy (`multiplier_resolution`, at the flow's
        rtol). A stick phase's multipliers are zero exactly (the saltation
        matrix of slip to stick has a zero row), so they come out at rounding,
        unresolved.
    - `multiplier_resolution`: the bound, shape ().
    - `stable`: all non-trivial multipliers inside the unit circle, shape ().
    - `residual`: max-norm of the shooting residual, shape ().
    - `converged`: whether Newton's method converged, shape ().

    All quantities are dimensionless (eqs. (4)-(6)).
    """

    params: ChainParams
    y0: State
    period: Float[Array, ""]
    amplitudes: Float[Array, " n_osc"]
    energy: Float[Array, ""]
    on_halc: Bool[Array, " n_osc"]
    n_halc: Int[Array, ""]
    multipliers: Complex[Array, " 2n"]
    trivial: Int[Array, ""]
    zero_multipliers: Int[Array, ""]
    resolved: Bool[Array, " 2n"]
    multiplier_resolution: Float[Array, ""]
    stable: Bool[Array, ""]
    residual: Float[Array, ""]
    converged: Bool[Array, ""]

    __repr__ = values_repr

    @property
    def critical_multiplier(self) -> Complex[Array, ""]:
        """The largest non-trivial multiplier in modulus (batched like `trivial`)."""
        return critical_multiplier(self.multipliers, self.trivial)


def describe_exact_orbit(params: ChainParams, u: Float[Array, " 2n+1"],
                         options: ExactShooting, converged=True) -> ExactOrbit:
    """The `ExactOrbit` of the shooting unknowns `u` (traceable)."""
    y0, period = unpack(u)
    m = exact_monodromy(params, y0, period, options)
    multipliers, trivial = _deflated(params, y0, m)
    resolution = multiplier_resolution(m, multipliers[trivial], options.flow.rtol)
    ts = period * jnp.linspace(0.0, 1.0, options.n_samples + 1)[1:]
    ys, status = nonsmooth_flow(params, y0, ts, options.flow)
    ys = jnp.where(status == Status.ok, ys, jnp.nan)
    amplitudes = 0.5 * (ys[:, 0].max(0) - ys[:, 0].min(0))
    on_halc = jnp.any(ys[:, 1] == params.v_d, axis=0)
    others = jnp.where(jnp.arange(multipliers.size) == trivial, 0.0, jnp.abs(multipliers))
    residual = jnp.max(jnp.abs(exact_shooting_residual(u, params, options)))
    return ExactOrbit(
        params=params, y0=y0, period=period, amplitudes=amplitudes,
        energy=0.5 * jnp.sum(amplitudes**2), on_halc=on_halc, n_halc=jnp.sum(on_halc),
        multipliers=multipliers, trivial=trivial,
        zero_multipliers=jnp.sum(jnp.abs(multipliers) < 1e-9),
        resolved=jnp.abs(multipliers) > resolution, multiplier_resolution=resolution,
        stable=jnp.all(others < 1),
        residual=residual,
        converged=jnp.asarray(converged) & (residual <= 1e3 * options.newton_tol))


@checks_as_nan
@eqx.filter_jit
def _root(params, u0, options):
    tol = options.newton_tol
    sol = optx.root_find(lambda u, p: exact_shooting_residual(u, p, options),
                         optx.Newton(rtol=tol, atol=tol), u0, params,
                         max_steps=options.newton_steps, throw=False)
    return sol.value, sol.result == optx.RESULTS.successful


@checks_as_nan
@eqx.filter_jit
def _damped_root(params, u0, options):
    """Newton steps (optimistix's Gauss-Newton with the Newton descent: the same
    linear solve on a square system) shortened by backtracking until the squared
    residual decreases enough (Armijo)."""
    tol = options.newton_tol
    solver = eqx.tree_at(lambda s: s.search,
                         optx.GaussNewton(rtol=tol, atol=tol, norm=optx.max_norm),
                         optx.BacktrackingArmijo())
    sol = optx.least_squares(lambda u, p: exact_shooting_residual(u, p, options), solver,
                             u0, params, max_steps=options.damped_steps, throw=False)
    return sol.value, sol.result == optx.RESULTS.successful


def _solve(params, u0, options):
    u, ok = _root(params, u0, options)
    if not bool(ok) and options.damped_steps:
        # it may stop at a minimum of the residual that is not a root, or short of
        # its tolerance: Newton's method from where it stopped decides
        u, ok = _root(params, _damped_root(params, u0, options)[0], options)
    # the record by continuation's own program (`describe_point`), compiled once
    orbit = describe_point(DescribeExactOrbit(options), u, params, params.v_d, "v_d")
    return eqx.tree_at(lambda o: o.converged, orbit, orbit.converged & ok)


def exact_periodic_orbit(params: ChainParams, y0: State, period: float,
                         options: ExactShooting = ExactShooting(), *,
                         throw: bool = True) -> ExactOrbit:
    """Solve for a periodic orbit of the exact stick/slip switch model (eq. (5) with
    the friction law of eqs. (1)-(2), stick exact) by single shooting on the exact
    engine: optimistix's Newton method on `exact_shooting_residual` (state and
    period, phase condition x_n'(0) = 0), its Jacobian by forward-mode
    differentiation through every switch; where it fails, the damped Newton
    method (`ExactShooting.damped_steps`) from the same guess, finished by
    Newton's method. Its Floquet multipliers are the
    eigenvalues of the exact monodromy matrix (`exact_monodromy`), with no eps:
    the limit that the smoothed model's multipliers approach as eps -> 0.

    **Arguments:**

    - `params`: the chain parameters.
    - `y0`: a guess of a state on the orbit, shape (2, n_osc); a state from a long
        simulation, for instance. Its velocity x_n' (n = `options.phase_oscillator`)
        is set to 0 first.
    - `period`: a guess of the period (> 0).
    - `options`: `ExactShooting`.
    - `throw`: raise if Newton's method does not converge (default); otherwise
        return the orbit with `converged=False`.

    **Returns:**

    An `ExactOrbit`.

    **Raises:**

    `ValidationError` for a guess of the wrong shape, a non-positive period or a
    phase oscillator outside the chain; `RuntimeError` if Newton's method does not
    converge and `throw=True`.
    """
    orbit = _solve(params, shooting_guess(params, y0, period, options), options)
    if throw and not bool(orbit.converged):
        raise RuntimeError("exact shooting did not converge: start from a state closer to "
                           "the orbit (after a longer simulation) or a better period guess")
    return orbit


class ExactShootingResidual(eqx.Module):
    """`exact_shooting_residual` with its options, as a `ContinuationProblem`
    residual (equal options give equal residuals: continuation compiles once)."""

    options: ExactShooting

    def __call__(self, u, params):
        return exact_shooting_residual(u, params, self.options)


class DescribeExactOrbit(eqx.Module):
    """`describe_exact_orbit` with its options, as a `ContinuationProblem` record."""

    options: ExactShooting

    def __call__(self, u, params):
        return describe_exact_orbit(params, u, self.options)


def exact_cycle_problem(orbit: ExactOrbit, options: ExactShooting = ExactShooting(),
                        where="v_d") -> ContinuationProblem:
    """The `ContinuationProblem` of the exact periodic orbits through `orbit`:
    unknowns (y0, T) of `exact_shooting_residual`, records `describe_exact_orbit`
    (exact Floquet multipliers, stability, n_HALC), to follow with `continuation`
    (pseudo-arclength, Keller 1977) in any parameter.

    **Arguments:**

    - `orbit`: a converged `ExactOrbit`.
    - `options`: `ExactShooting` of every point.
    - `where`: the continued parameter, a name or a lens (default the belt speed).
    """
    return ContinuationProblem(
        residual=ExactShootingResidual(options), u0=pack(orbit.y0, orbit.period),
        params=orbit.params, where=where, describe=DescribeExactOrbit(options))
