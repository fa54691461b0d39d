"""Periodic orbits of eq. (5) by single shooting, and their Floquet multipliers from
the monodromy matrix."""

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import optimistix as optx
from jaxtyping import Array, Bool, Complex, Float

from .._engine.compat import checks_as_nan, errors_as_nan
from .._physics.custom_types import State
from .._physics.forces import DEFAULT_EPS
from .._physics.model import Model, model_field, vector_field
from .._physics.params import ChainParams
from .._physics.stick import min_slip_speed, sticks
from .._checks import check_positive
from .continuation import describe_point
from .hopf import check_eps
from .._errors import ValidationError
from .._printing import values_repr


class ShootingOptions(eqx.Module):
    """How periodic orbits are integrated and solved for.

    **Arguments:**

    - `solver`: diffrax solver of the flow over one period. Shooting asks for
        accuracy (the trivial Floquet multiplier is 1 only as far as the flow is
        exact), so an accurate explicit method is the default.
    - `rtol`, `atol`: tolerances of the flow (diffrax's `PIDController`).
    - `max_steps`: step budget of one period.
    - `newton_tol`: Newton's tolerance (optimistix, rtol = atol) on the state and
        period.
    - `newton_steps`: Newton's iteration budget.
    - `n_samples`: samples of one period from which amplitudes are taken.
    - `phase_oscillator`: the oscillator n of the phase condition x_n'(0) = 0
        (0-based); choose one that vibrates, so that the section is crossed
        transversally.
    - `root_finder`: `"newton"` (optimistix's Newton, fast near the orbit) or
        `"levenberg-marquardt"` (optimistix's Levenberg-Marquardt on the same
        residual: a damped Newton method that converges from the rougher guesses of
        a simulated chain, where the flow's derivative is large across each
        stick-slip switch; More, *The Levenberg-Marquardt algorithm* (1978)).

    **Raises:**

    `ValidationError` naming the field for a non-positive tolerance or count.
    """

    solver: diffrax.AbstractSolver = diffrax.Tsit5()
    rtol: float = eqx.field(static=True, default=1e-10)
    atol: float = eqx.field(static=True, default=1e-12)
    max_steps: int = eqx.field(static=True, default=200_000)
    newton_tol: float = eqx.field(static=True, default=1e-9)
    newton_steps: int = eqx.field(static=True, default=40)
    n_samples: int = eqx.field(static=True, default=4096)
    phase_oscillator: int = eqx.field(static=True, default=0)
    root_finder: str = eqx.field(static=True, default="newton")

    def __check_init__(self):
        if self.phase_oscillator < 0:
            raise ValidationError(f"ShootingOptions.phase_oscillator must be >= 0, got "
                                  f"{self.phase_oscillator!r}")
        if self.root_finder not in ("newton", "levenberg-marquardt"):
            raise ValidationError(f"ShootingOptions.root_finder must be 'newton' or "
                                  f"'levenberg-marquardt', got {self.root_finder!r}")
        for name in ("rtol", "atol", "max_steps", "newton_tol", "newton_steps", "n_samples"):
            value = getattr(self, name)
            if not value > 0:
                raise ValidationError(f"ShootingOptions.{name} must be > 0, got {value!r}")


def flow(params: ChainParams, y0: State, period, options: ShootingOptions,
         saveat: diffrax.SaveAt = diffrax.SaveAt(t1=True), *,
         eps=DEFAULT_EPS) -> diffrax.Solution:
    """Integrate eq. (5), its friction smoothed as tanh(v_rel/eps), from `y0` over
    [0, period]. Forward-mode differentiable (`diffrax.ForwardMode`), for monodromy
    matrices and Newton's method.

    **Arguments:**

    - `params`: the chain parameters.
    - `y0`: the state at t = 0, shape (2, n_osc).
    - `period`: the end time, > 0, dimensionless.
    - `options`: `ShootingOptions` (solver and tolerances).
    - `saveat`: diffrax's `SaveAt` (the end state by default).
    - `eps`: the smoothing velocity of tanh(v_rel/eps) (> 0), shape (),
        dimensionless (a fraction of x_0 omega_n); the smoothed engine's
        (`Smoothed.eps`), `DEFAULT_EPS` by default.
    """
    with errors_as_nan():  # diffrax's checks of its arguments: no host callback
        return diffrax.diffeqsolve(
            diffrax.ODETerm(model_field), options.solver, 0.0, period, None, y0,
            Model(params, eps),
            saveat=saveat, max_steps=options.max_steps, adjoint=diffrax.ForwardMode(),
            stepsize_controller=diffrax.PIDController(rtol=options.rtol,
                                                      atol=options.atol),
            throw=False)


def pack(y0: State, period) -> Float[Array, " 2n+1"]:
    """The unknowns of shooting, (x_1..x_N, x_1'..x_N', T)."""
    return jnp.concatenate([jnp.reshape(y0, (-1,)), jnp.atleast_1d(period)])


def unpack(u: Float[Array, " 2n+1"]) -> tuple[State, Float[Array, ""]]:
    """Inverse of `pack`."""
    return jnp.reshape(u[:-1], (2, -1)), u[-1]


def shooting_residual(u: Float[Array, " 2n+1"], params: ChainParams,
                      options: ShootingOptions, eps=DEFAULT_EPS) -> Float[Array, " 2n+1"]:
    """Single-shooting residual of a periodic orbit (Seydel, *Practical Bifurcation
    and Stability Analysis*, 3rd ed. (2010), Sect. 7.1): the flow over one period
    minus the start, phi_T(y0) - y0, and the phase condition x_n'(0) = 0 with n =
    `options.phase_oscillator` (the orbit starts at a turning point of oscillator
    n, a Poincare section crossed by every stick-slip and every small Hopf cycle in
    which n vibrates).

    **Arguments:**

    - `u`: the unknowns `pack(y0, T)`, shape (2 n_osc + 1,).
    - `params`: the chain parameters.
    - `options`: `ShootingOptions`.
    - `eps`: the smoothing velocity of tanh(v_rel/eps) (> 0), shape (),
        dimensionless; the smoothed engine's (`Smoothed.eps`), `DEFAULT_EPS` by
        default.

    **Returns:**

    Shape (2 n_osc + 1,); zero on a periodic orbit.
    """
    y0, period = unpack(u)
    y1 = flow(params, y0, period, options, eps=eps).ys[-1]
    n = options.phase_oscillator
    return jnp.concatenate([jnp.reshape(y1 - y0, (-1,)), y0[1, n:n + 1]])


def monodromy(params: ChainParams, y0: State, period, options: ShootingOptions,
              eps=DEFAULT_EPS) -> Float[Array, "2n 2n"]:
    """The monodromy matrix d phi_T(y0) / d y0 of the flow smoothed at `eps` (> 0,
    dimensionless; `DEFAULT_EPS` by default, as `flow` takes it), by forward-mode
    differentiation through `diffrax.diffeqsolve` (`jax.jacfwd`). Ordered as
    `jacobian`."""
    def end(z):
        return jnp.reshape(flow(params, jnp.reshape(z, (2, -1)), period, options,
                                eps=eps).ys[-1], (-1,))
    return jax.jacfwd(end)(jnp.reshape(y0, (-1,)))


def floquet_multipliers(params: ChainParams, y0: State, period, options: ShootingOptions,
                        eps=DEFAULT_EPS) -> tuple[Complex[Array, " 2n"], Array]:
    """Floquet multipliers of the orbit through `y0` of the flow smoothed at `eps`
    (> 0, shape (), dimensionless; `DEFAULT_EPS` by default, as `flow` takes it),
    with the trivial one deflated.

    The flow direction f = f(y0) is an eigenvector of the monodromy matrix M with
    multiplier 1 on an exact orbit. In an orthonormal basis [f/|f|, V] (Householder
    QR of f), M is block upper triangular up to the flow's error, so the
    non-trivial multipliers are the eigenvalues of V^T M V (the linearized
    Poincare map on the quotient by the flow direction), and the trivial one is
    the Rayleigh quotient f^T M f / |f|^2. No multiplier near 1 (a weakly damped
    quiet oscillator, a slowly drifting phase between sites) can then be taken for
    the trivial one (Seydel, *Practical Bifurcation and Stability Analysis*,
    3rd ed., Sect. 7.4; Wielandt deflation).

    **Returns:**

    (multipliers of shape (2 n_osc,), complex, by decreasing modulus: the 2 n_osc - 1
    non-trivial ones and the trivial one; index of the trivial one, shape ()).
    Its distance from 1 measures the accuracy of the flow.
    """
    return _deflated(params, y0, monodromy(params, y0, period, options, eps), eps)


def _deflated(params: ChainParams, y0: State, m: Float[Array, "2n 2n"], eps
              ) -> tuple[Complex[Array, " 2n"], Array]:
    """The multipliers of the monodromy `m` of the orbit through `y0`, the trivial
    one (of the vector field at y0) deflated."""
    return deflated_multipliers(m, jnp.reshape(vector_field(0.0, y0, params, eps), (-1,)))


def deflated_multipliers(m: Float[Array, "2n 2n"], direction: Float[Array, " 2n"]
                         ) -> tuple[Complex[Array, " 2n"], Array]:
    """The eigenvalues of a monodromy matrix `m`, the trivial one (of the flow
    direction `direction`, the vector field at the orbit's start) deflated as
    `floquet_multipliers` describes: (multipliers by decreasing modulus, index of
    the trivial one)."""
    direction = direction / jnp.linalg.norm(direction)
    basis, _ = jnp.linalg.qr(direction[:, None], mode="complete")
    rest = basis[:, 1:]
    values = jnp.concatenate([jnp.linalg.eigvals(rest.T @ m @ rest),
                              (direction @ m @ direction)[None].astype(complex)])
    order = jnp.argsort(-jnp.abs(values))
    return values[order], jnp.argmax(order == values.size - 1)


def jacobian_trace(params: ChainParams, y: State, eps=DEFAULT_EPS) -> Float[Array, ""]:
    """The trace of the Jacobian of eq. (5), smoothed at `eps`, at the state `y`
    (shape (2, n_osc)): the sum over the oscillators of d x_n'' / d x_n'. The
    positions' rows add nothing (x' = v), and each acceleration depends on its own
    velocity only (damping and friction act on each oscillator, the coupling on
    positions), so the velocity block is diagonal and its diagonal is one
    Jacobian-vector product along all-ones velocities:
    sum_n (-2 xi_n + dF_n/dv_n) / m_n."""
    x, v = y[0], y[1]

    def acceleration(v):
        return vector_field(0.0, jnp.stack([x, v]), params, eps)[1]

    _, diagonal = jax.jvp(acceleration, (v,), (jnp.ones_like(v),))
    return jnp.sum(diagonal)


def _liouville_field(t, z, model: Model):
    """Eq. (5) and, beside it, the trace of its Jacobian (`jacobian_trace`), whose
    integral over a period is the logarithm of the monodromy's determinant."""
    y, _ = z
    return model_field(t, y, model), jacobian_trace(model.params, y, model.eps)


def _orbit_extrema(params: ChainParams, y0: State, period, options: ShootingOptions,
                   eps) -> tuple[Float[Array, " n_osc"], Float[Array, " n_osc"],
                                 Float[Array, " n_osc"], Float[Array, ""]]:
    """(x_max, x_min, smallest slip speed |x' - v_d|) of each oscillator over one
    period, from `options.n_samples` dense-output samples, and the integral of
    the Jacobian's trace over the period (`jacobian_trace`), integrated alongside
    as one more state at the same tolerances."""
    ts = period * jnp.linspace(0.0, 1.0, options.n_samples)
    with errors_as_nan():  # as `flow`
        ys, log_det = diffrax.diffeqsolve(
            diffrax.ODETerm(_liouville_field), options.solver, 0.0, period, None,
            (y0, jnp.zeros(())), Model(params, eps), saveat=diffrax.SaveAt(ts=ts),
            max_steps=options.max_steps, adjoint=diffrax.ForwardMode(),
            stepsize_controller=diffrax.PIDController(rtol=options.rtol,
                                                      atol=options.atol),
            throw=False).ys
    return (ys[:, 0].max(0), ys[:, 0].min(0), min_slip_speed(ys[:, 1], params.v_d),
            log_det[-1])


def multiplier_resolution(m: Float[Array, "2n 2n"], trivial_multiplier, rtol
                          ) -> Float[Array, ""]:
    """The smallest modulus a Floquet multiplier of the computed monodromy `m` can be
    told from zero by: the error of `m` itself, estimated as the larger of
    |m|_2 max(rtol, machine epsilon) (the flow's relative tolerance `rtol`, or
    rounding) and the trivial multiplier's distance from 1 (the error the flow
    shows in the one direction whose multiplier is known). An eigenvalue moves by
    about the error of the matrix (Bauer-Fike, for a well-conditioned one), so a
    multiplier below the bound is rounding or integration noise: its sign, its
    phase and its size mean nothing."""
    floor = jnp.maximum(rtol, jnp.finfo(m.dtype).eps)
    return jnp.maximum(jnp.linalg.norm(m, 2) * floor, jnp.abs(trivial_multiplier - 1))


class PeriodicOrbit(eqx.Module):
    """A periodic orbit of eq. (5) and its stability.

    **Fields:**

    - `params`: the parameters it belongs to.
    - `eps`: the smoothing velocity of the flow it is an orbit of (tanh(v_rel/eps)),
        shape (), dimensionless.
    - `y0`: the state at t = 0 (x_1'(0) = 0), shape (2, n_osc).
    - `period`: T, shape ().
    - `amplitudes`: half of peak-to-peak of each x_n, shape (n_osc,).
    - `energy`: E = 1/2 sum_n A_n^2 (eq. (9) of the paper), shape ().
    - `n_halc`: oscillators on the HALC: they stick, their smallest slip speed
        |x_n' - v_d| over `options.n_samples` samples of the period is <= 3 eps
        (`sticks`), shape ().
    - `multipliers`: Floquet multipliers by decreasing modulus, shape (2 n_osc,).
    - `trivial`: index of the trivial multiplier, shape ().
    - `resolved`: whether each multiplier lies above `multiplier_resolution` in
        modulus, shape (2 n_osc,). An unresolved one is zero as far as the
        computed monodromy tells (a stick phase contracts the velocity by about
        exp(-mu_st T_stick / eps), far below any tolerance): its value, sign
        included, is noise, and its size is only bounded.
    - `multiplier_resolution`: the bound (`multiplier_resolution`), shape ().
    - `monodromy_determinant`: det M by Liouville's formula, exp of the integral of
        the Jacobian's trace over the period (`jacobian_trace`), integrated
        beside the orbit: the product of all the multipliers, resolved or not
        (the non-trivial ones' product where the trivial one is 1), to the
        integration tolerance relative, however small, shape ().
    - `stable`: all non-trivial multipliers inside the unit circle, shape ().
    - `residual`: max-norm of the shooting residual, shape ().
    - `converged`: whether Newton's method converged, shape ().

    All quantities are dimensionless (eqs. (4)-(6)).
    """

    params: ChainParams
    eps: Float[Array, ""]
    y0: State
    period: Float[Array, ""]
    amplitudes: Float[Array, " n_osc"]
    energy: Float[Array, ""]
    n_halc: Array
    multipliers: Complex[Array, " 2n"]
    trivial: Array
    resolved: Bool[Array, " 2n"]
    multiplier_resolution: Float[Array, ""]
    monodromy_determinant: Float[Array, ""]
    stable: Bool[Array, ""]
    residual: Float[Array, ""]
    converged: Bool[Array, ""]

    __repr__ = values_repr

    @property
    def critical_multiplier(self) -> Complex[Array, ""]:
        """The largest non-trivial multiplier in modulus (batched like `trivial`)."""
        return critical_multiplier(self.multipliers, self.trivial)


def critical_multiplier(multipliers: Complex[Array, "... 2n"], trivial: Array
                        ) -> Complex[Array, "..."]:
    """The largest multiplier in modulus other than the trivial one, of multipliers
    sorted by decreasing modulus (batched like `trivial`)."""
    index = jnp.where(trivial == 0, 1, 0)
    return jnp.take_along_axis(multipliers, index[..., None], axis=-1)[..., 0]


def describe_orbit(params: ChainParams, u: Float[Array, " 2n+1"], options: ShootingOptions,
                   converged=True, eps=DEFAULT_EPS) -> PeriodicOrbit:
    """The `PeriodicOrbit` of the shooting unknowns `u` of the flow smoothed at `eps`
    (> 0, shape (), dimensionless; `DEFAULT_EPS` by default) (traceable)."""
    eps = jnp.asarray(eps, dtype=float)
    y0, period = unpack(u)
    m = monodromy(params, y0, period, options, eps)
    multipliers, trivial = _deflated(params, y0, m, eps)
    resolution = multiplier_resolution(m, multipliers[trivial], options.rtol)
    x_max, x_min, slip_speed, log_det = _orbit_extrema(params, y0, period, options, eps)
    amplitudes = 0.5 * (x_max - x_min)
    others = jnp.where(jnp.arange(multipliers.size) == trivial, 0.0, jnp.abs(multipliers))
    residual = jnp.max(jnp.abs(shooting_residual(u, params, options, eps)))
    n_halc = jnp.sum(sticks(slip_speed, eps))
    return PeriodicOrbit(
        params=params, eps=eps, y0=y0, period=period, amplitudes=amplitudes,
        energy=0.5 * jnp.sum(amplitudes**2), n_halc=n_halc,
        multipliers=multipliers, trivial=trivial,
        resolved=jnp.abs(multipliers) > resolution, multiplier_resolution=resolution,
        monodromy_determinant=jnp.exp(log_det), stable=jnp.all(others < 1),
        residual=residual, converged=jnp.asarray(converged))


class DescribeOrbit(eqx.Module):
    """`describe_orbit` with its options and smoothing velocity bound, as a
    `ContinuationProblem` record (fields as `ShootingResidual`)."""

    options: ShootingOptions
    eps: Float[Array, ""] = eqx.field(converter=check_eps, default=DEFAULT_EPS)

    def __call__(self, u, params):
        return describe_orbit(params, u, self.options, eps=self.eps)


@checks_as_nan
@eqx.filter_jit
def _root(params, eps, u0, options):
    def fn(u, p):
        return shooting_residual(u, p, options, eps)

    tol = options.newton_tol
    if options.root_finder == "newton":
        sol = optx.root_find(fn, optx.Newton(rtol=tol, atol=tol), u0, params,
                             max_steps=options.newton_steps, throw=False)
    else:  # forward-mode Jacobian: the flow is differentiated with ForwardMode
        sol = optx.least_squares(fn, optx.LevenbergMarquardt(rtol=tol, atol=tol), u0, params,
                                 options={"jac": "fwd"}, max_steps=5 * options.newton_steps,
                                 throw=False)
    return sol.value, sol.result == optx.RESULTS.successful


def _solve(params, eps, u0, options):
    u, ok = _root(params, eps, u0, options)
    # the record by continuation's own program (`describe_point`), compiled once
    orbit = describe_point(DescribeOrbit(options, eps), u, params, params.v_d, "v_d")
    # Levenberg-Marquardt also stops at a local minimum of the residual: only a root
    # counts as converged.
    return eqx.tree_at(lambda o: o.converged, orbit,
                       ok & (orbit.residual <= 1e3 * options.newton_tol))


def shooting_guess(params: ChainParams, y0: State, period, options) -> Float[Array, " 2n+1"]:
    """The unknowns `pack(y0, T)` of a checked guess, its phase oscillator's velocity
    set to 0 (the phase condition). `options` is `ShootingOptions` or
    `ExactShooting` (its `phase_oscillator`).

    **Raises:** `ValidationError` for a guess of the wrong shape, a non-positive
    period or a phase oscillator outside the chain."""
    y0 = jnp.asarray(y0, dtype=float)
    if y0.shape != (2, params.n_osc):
        raise ValidationError(f"y0 must have shape (2, {params.n_osc}), got {y0.shape}")
    check_positive("period", period)
    if options.phase_oscillator >= params.n_osc:
        raise ValidationError(f"{type(options).__name__}.phase_oscillator must be < n_osc = "
                              f"{params.n_osc}, got {options.phase_oscillator}")
    return pack(y0.at[1, options.phase_oscillator].set(0.0), period)


def periodic_orbit(params: ChainParams, y0: State, period: float,
                   options: ShootingOptions = ShootingOptions(), *, eps=DEFAULT_EPS,
                   throw: bool = True) -> PeriodicOrbit:
    """Solve for a periodic orbit of eq. (5) by single shooting: optimistix's Newton
    method on `shooting_residual` (state and period, with the phase condition
    x_1'(0) = 0), its Jacobian by forward-mode differentiation through
    `diffrax.diffeqsolve`. The Floquet multipliers are the eigenvalues of the
    monodromy matrix (`floquet_multipliers`).

    **Arguments:**

    - `params`: the chain parameters.
    - `y0`: a guess of a state on the orbit, shape (2, n_osc); a state from a long
        simulation, for instance. Its velocity x_n' (n = `options.phase_oscillator`)
        is set to 0 first.
    - `period`: a guess of the period.
    - `options`: `ShootingOptions`.
    - `eps`: the smoothing velocity of tanh(v_rel/eps) in eq. (5), a finite number
        > 0, shape (), dimensionless (a fraction of x_0 omega_n): the orbit is one
        of the smoothed engine's model at this eps (`Smoothed.eps`), `DEFAULT_EPS`
        by default. Traced: a new eps does not recompile.
    - `throw`: raise if Newton's method does not converge (default); otherwise
        return the orbit with `converged=False`.

    **Returns:**

    A `PeriodicOrbit`.

    **Raises:**

    `ValidationError` for a guess of the wrong shape, a non-positive period or eps, or
    a phase oscillator outside the chain;
    `RuntimeError` if Newton's method does not converge and `throw=True`.
    """
    u0 = shooting_guess(params, y0, period, options)
    orbit = _solve(params, check_eps(eps), u0, options)
    if throw and not bool(orbit.converged):
        raise RuntimeError("shooting did not converge: start from a state closer to the "
                           "orbit (after a longer simulation) or a better period guess")
    return orbit
