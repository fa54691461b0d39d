"""The orbit method as a value: `AbstractOrbitMethod` (what every way of computing a
periodic orbit provides) and the one `PeriodicOrbit` record they all describe, with
the Floquet multipliers' deflation and resolution that every method shares. A new
method (`Shooting` is the first) is one class: `periodic_orbit`, the continuation,
the bifurcations on its branch and the studies above take it as it is
(docs/adding-a-method.md)."""

import abc

import equinox as eqx
import jax.numpy as jnp
import lineax as lx
import optimistix as optx
from jaxtyping import Array, Bool, Complex, Float, Int

from .._engine.compat import checks_as_nan
from .._errors import ValidationError
from .._physics.custom_types import State
from .._physics.params import ChainParams
from .._printing import values_repr


class PeriodicOrbit(eqx.Module):
    """A periodic orbit of eq. (5) and its stability, as any orbit method gives it.

    **Fields:**

    - `params`: the parameters it belongs to.
    - `y0`: the state at t = 0, shape (2, n_osc); x_n'(0) = 0 for the method's
        phase oscillator n.
    - `period`: T, shape ().
    - `amplitudes`: half of peak-to-peak of each x_n over the method's samples of
        the period, shape (n_osc,).
    - `energy`: E = 1/2 sum_n A_n^2 (eq. (9) of the paper), shape ().
    - `on_halc`: whether each oscillator sticks during the period (the engine's
        stick: x_n' = v_d exactly for the exact engine, inside the stick band
        |x_n' - v_d| <= 3 eps for the smoothed one, `sticks`), shape (n_osc,).
    - `n_halc`: the number of them, shape ().
    - `multipliers`: Floquet multipliers by decreasing modulus, shape (2 n_osc,).
    - `trivial`: index of the trivial multiplier (of the flow direction), shape ().
    - `zero_multipliers`: multipliers of modulus below 1e-9 (a stick phase of the
        exact model loses its oscillator's velocity perturbation), shape ().
    - `resolved`: whether each multiplier lies above `multiplier_resolution` in
        modulus, shape (2 n_osc,). An unresolved one is zero as far as the
        computed monodromy tells: its value, sign included, is noise.
    - `multiplier_resolution`: the bound (`multiplier_resolution`), shape ().
    - `monodromy_determinant`: det M by Liouville's formula where the method's
        engine integrates it (the smoothed engine), NaN otherwise, shape ().
    - `stable`: all non-trivial multipliers inside the unit circle, shape ().
    - `residual`: max-norm of the method's residual, shape ().
    - `converged`: whether the solve converged and the residual is within 1e3
        times the method's Newton tolerance, shape ().

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


def deflated_multipliers(m: Float[Array, "2n 2n"], direction: Float[Array, " 2n"] | None
                         ) -> tuple[Complex[Array, " 2n"], Array]:
    """The eigenvalues of a monodromy matrix `m` by decreasing modulus, the trivial one
    (of the flow direction `direction`, the vector field at the orbit's start)
    deflated: (multipliers, index of the trivial one). A forced orbit has no
    trivial multiplier (`direction` None): its index is then 2 n_osc, past the end.

    The flow direction f is an eigenvector of M with multiplier 1 on an exact orbit.
    In an orthonormal basis [f/|f|, V] (Householder QR of f), M is block upper
    triangular up to the flow's error, so the non-trivial multipliers are the
    eigenvalues of V^T M V (the linearized Poincare map on the quotient by the flow
    direction), and the trivial one is the Rayleigh quotient f^T M f / |f|^2. No
    multiplier near 1 (a weakly damped quiet oscillator, a slowly drifting phase
    between sites) can then be taken for the trivial one (Seydel, *Practical
    Bifurcation and Stability Analysis*, 3rd ed., Sect. 7.4; Wielandt deflation)."""
    if direction is None:
        values = jnp.linalg.eigvals(m)
        return values[jnp.argsort(-jnp.abs(values))], jnp.asarray(values.size)
    direction = direction / jnp.linalg.norm(direction)
    basis, _ = jnp.linalg.qr(direction[:, None], mode="complete")
    rest = basis[:, 1:]
    values = jnp.concatenate([jnp.linalg.eigvals(rest.T @ m @ rest),
                              (direction @ m @ direction)[None].astype(complex)])
    order = jnp.argsort(-jnp.abs(values))
    return values[order], jnp.argmax(order == values.size - 1)


def multiplier_resolution(m: Float[Array, "2n 2n"], trivial_multiplier, rtol
                          ) -> Float[Array, ""]:
    """The smallest modulus a Floquet multiplier of the computed monodromy `m` can be
    told from zero by: the error of `m` itself, estimated as the larger of
    |m|_2 max(rtol, machine epsilon) (the flow's relative tolerance `rtol`, or
    rounding) and the trivial multiplier's distance from 1 (the error the flow
    shows in the one direction whose multiplier is known). An eigenvalue moves by
    about the error of the matrix (Bauer-Fike, for a well-conditioned one), so a
    multiplier below the bound is rounding or integration noise."""
    floor = jnp.maximum(rtol, jnp.finfo(m.dtype).eps)
    return jnp.maximum(jnp.linalg.norm(m, 2) * floor, jnp.abs(trivial_multiplier - 1))


def orbit_record(params: ChainParams, y0: State, period, ys: Float[Array, "m 2 n"],
                 on_halc, m: Float[Array, "2n 2n"], direction, rtol, log_det, residual,
                 converged) -> PeriodicOrbit:
    """The `PeriodicOrbit` of an orbit through `y0` of period `period`, from the
    pieces a method computes: samples `ys` of the period, which oscillators stick
    there, its monodromy `m` with the flow direction at y0 and the flow's `rtol`,
    the logarithm of det M (or NaN), its residual's max-norm and whether the solve
    converged (traceable). `direction` is `flow_direction`'s: None for a forced
    orbit, which has no trivial multiplier."""
    multipliers, trivial = deflated_multipliers(m, direction)
    resolution = multiplier_resolution(
        m, 1.0 if direction is None else multipliers[trivial], rtol)
    amplitudes = 0.5 * (ys[:, 0].max(0) - ys[:, 0].min(0))
    others = jnp.where(jnp.arange(multipliers.size) == trivial, 0.0, jnp.abs(multipliers))
    return PeriodicOrbit(
        params=params, y0=y0, period=period, amplitudes=amplitudes,
        energy=0.5 * jnp.sum(amplitudes**2), on_halc=on_halc, n_halc=jnp.sum(on_halc),
        multipliers=multipliers, trivial=trivial,
        zero_multipliers=jnp.sum(jnp.abs(multipliers) < 1e-9),
        resolved=jnp.abs(multipliers) > resolution, multiplier_resolution=resolution,
        monodromy_determinant=jnp.exp(log_det), stable=jnp.all(others < 1),
        residual=residual, converged=jnp.asarray(converged))


def flow_direction(engine, params: ChainParams, y0: State) -> Float[Array, " 2n"] | None:
    """The vector field at the orbit's start, flattened: the eigenvector of the
    trivial Floquet multiplier of an autonomous chain; None for a forced chain
    (`ChainParams.forcing`), whose orbits have none."""
    if params.forcing is not None:
        return None
    return jnp.reshape(engine.field(params, y0), (-1,))


def closing_condition(params: ChainParams, phase: Float[Array, ""], period
                      ) -> Float[Array, " 1"]:
    """The last equation of every method's residual, shape (1,): the phase condition
    (`phase`, x_n'(0) of the method's phase oscillator or a multiple of it) for an
    autonomous chain, whose orbits can start anywhere on themselves; for a forced
    chain, whose time origin is the force's, the period of the force:
    T - 2 pi / Omega."""
    if params.forcing is None:
        return jnp.reshape(phase, (1,))
    return jnp.reshape(period - params.forcing.period, (1,))


def guess_period(params: ChainParams, period):
    """The period of a guess: `period` for an autonomous chain, the force's 2 pi /
    Omega for a forced one (whose orbits have that period)."""
    return period if params.forcing is None else params.forcing.period


def phased_guess(method, params: ChainParams, y0) -> State:
    """The guess's state `y0` checked against the chain, with the velocity of the
    method's phase oscillator set to 0 (the phase condition x_n'(0) = 0) on an
    autonomous chain (a forced one's start is fixed by the force's phase).

    **Raises:** `ValidationError` for a state of the wrong shape or a phase
    oscillator outside the chain."""
    y0 = jnp.asarray(y0, dtype=float)
    if y0.shape != (2, params.n_osc):
        raise ValidationError(f"y0 must have shape (2, {params.n_osc}), got {y0.shape}")
    if method.phase_oscillator >= params.n_osc:
        raise ValidationError(f"{type(method).__name__}.phase_oscillator must be < n_osc = "
                              f"{params.n_osc}, got {method.phase_oscillator}")
    if params.forcing is not None:
        return y0
    return y0.at[1, method.phase_oscillator].set(0.0)


class AbstractOrbitMethod(eqx.Module):
    """A way of computing periodic orbits of eq. (5): unknowns u that hold one orbit,
    a residual that vanishes on it, and the orbit's description. `periodic_orbit`
    solves for one, `cycle_problem` follows its branch with `continuation`; neither
    asks which method it has.

    A subclass implements `unknowns`, `orbit`, `residual`, `describe` and `samples`,
    and `pack` where a state and a period determine its unknowns (else `start`), and
    may replace `solve` (Newton's method by optimistix on `residual` by default).
    `Shooting` is the first."""

    newton_tol: eqx.AbstractVar[float]
    newton_steps: eqx.AbstractVar[int]

    @abc.abstractmethod
    def unknowns(self, params: ChainParams, y0: State, period) -> Float[Array, " n"]:
        """The method's unknowns of a guess: a state on the orbit (shape (2, n_osc))
        and its period. Raises `ValidationError` for a guess it cannot take."""

    def pack(self, y0: State, period) -> Float[Array, " n"]:
        """The unknowns of the orbit through y0 with its period, as they are (a
        converged orbit's; traceable), where a state and a period determine them.
        Raises `ValidationError` where they do not."""
        raise ValidationError(f"{type(self).__name__} cannot take its unknowns from a "
                              "state and a period alone")

    def start(self, orbit: PeriodicOrbit) -> Float[Array, " n"]:
        """The unknowns of the converged `orbit`, to continue from (`cycle_problem`):
        `pack(orbit.y0, orbit.period)` by default."""
        return self.pack(orbit.y0, orbit.period)

    @abc.abstractmethod
    def orbit(self, u: Float[Array, " n"]) -> tuple[State, Float[Array, ""]]:
        """(The state at t = 0, shape (2, n_osc); the period) of the unknowns u."""

    @abc.abstractmethod
    def residual(self, u: Float[Array, " n"], params: ChainParams) -> Float[Array, " n"]:
        """The residual of the unknowns u at `params`: zero on a periodic orbit."""

    @abc.abstractmethod
    def describe(self, u: Float[Array, " n"], params: ChainParams) -> PeriodicOrbit:
        """The `PeriodicOrbit` of the unknowns u (traceable; `orbit_record`)."""

    @abc.abstractmethod
    def samples(self, params: ChainParams, u: Float[Array, " n"], ts) -> Array:
        """The orbit's states at the times `ts` (increasing, > 0, within a period),
        shape (m, 2, n_osc)."""

    def multipliers(self, params: ChainParams, u: Float[Array, " n"]
                    ) -> tuple[Complex[Array, " 2n"], Int[Array, ""]]:
        """(The Floquet multipliers of the orbit u by decreasing modulus, the index of
        the trivial one). Raises `ValidationError` where the method gives none."""
        raise ValidationError(f"{type(self).__name__} gives no Floquet multipliers")

    def solve(self, params: ChainParams, u0: Float[Array, " n"]
              ) -> tuple[Float[Array, " n"], Bool[Array, ""]]:
        """(The unknowns solved from the guess u0; whether the solver converged):
        optimistix's Newton method on `residual` by default."""
        return _newton(self, params, u0)

    def with_phase_oscillator(self, n: int) -> "AbstractOrbitMethod":
        """The method with its phase condition on oscillator n (0-based)."""
        raise ValidationError(f"{type(self).__name__} has no phase oscillator to choose")

    def refine(self, factor: float) -> "AbstractOrbitMethod":
        """The method `factor` times more accurate, to check a result (its flow's
        tolerances divided by `factor`). Raises `ValidationError` where the method
        has no accuracy to change."""
        raise ValidationError(f"{type(self).__name__} has no accuracy to refine")


def damped_newton(method: AbstractOrbitMethod, params: ChainParams, u0, max_steps: int,
                  linear_solver: lx.AbstractLinearSolver = lx.AutoLinearSolver(well_posed=None),
                  adjoint_solver: lx.AbstractLinearSolver | None = None):
    """(The unknowns; whether it converged) by Newton steps on `method.residual`
    (optimistix's Gauss-Newton with the Newton descent: the same linear solve on a
    square system) shortened by backtracking until the squared residual decreases
    enough (Armijo; Dennis and Schnabel, *Numerical Methods for Unconstrained
    Optimization and Nonlinear Equations* (1996), Sect. 6.3): full Newton steps near
    the root, short ones where a full step would leave its neighbourhood.
    Traceable; differentiable by the implicit function theorem. `linear_solver`
    (lineax) solves each step's linear system (LU by default), `adjoint_solver`
    the derivatives' (`linear_solver` by default): optimistix differentiates a
    least-squares solution through the Jacobian of its optimality condition,
    J^T J and the residual's curvature, which has not J's sparsity."""
    tol = method.newton_tol
    solver = eqx.tree_at(lambda s: s.search,
                         optx.GaussNewton(rtol=tol, atol=tol, norm=optx.max_norm,
                                          linear_solver=linear_solver),
                         optx.BacktrackingArmijo())
    sol = optx.least_squares(lambda u, p: method.residual(u, p), solver, u0, params,
                             max_steps=max_steps, throw=False,
                             adjoint=optx.ImplicitAdjoint(linear_solver=linear_solver
                                                          if adjoint_solver is None
                                                          else adjoint_solver))
    # converged also where the residual vanishes to the tolerance but the search,
    # unable to lower a residual at rounding level, rejected every later step
    # (optimistix then runs out of steps without testing the termination)
    small = jnp.max(jnp.abs(method.residual(sol.value, params))) <= tol
    return sol.value, (sol.result == optx.RESULTS.successful) | small


@checks_as_nan
@eqx.filter_jit
def _newton(method: AbstractOrbitMethod, params: ChainParams, u0):
    tol = method.newton_tol
    sol = optx.root_find(lambda u, p: method.residual(u, p), optx.Newton(rtol=tol, atol=tol),
                         u0, params, max_steps=method.newton_steps, throw=False)
    return sol.value, sol.result == optx.RESULTS.successful
