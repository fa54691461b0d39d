"""Periodic orbits by single shooting on either engine: the flow over one period
(`AbstractEngine.flow`) with its sensitivities, Newton's method on the period map,
and the Floquet multipliers from the monodromy matrix."""

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import optimistix as optx
from jaxtyping import Array, Float

from .._engine.compat import checks_as_nan
from .._engine.engines import AbstractEngine, Smoothed
from .._errors import ValidationError
from .._physics.custom_types import State
from .._physics.params import ChainParams
from .orbit_method import (AbstractOrbitMethod, PeriodicOrbit, closing_condition,
                           damped_newton, deflated_multipliers, flow_direction, guess_period,
                           orbit_record, phased_guess)

#: The root finders of `Shooting`.
ROOT_FINDERS = ("newton", "levenberg-marquardt")

#: The flow's largest relative tolerance `Shooting` takes: multipliers and the
#: orbit are only as accurate as the flow.
LOOSEST_RTOL = 1e-6


def pack(y0: State, period) -> Float[Array, " 2n+1"]:
    """The unknowns of shooting, (x_1..x_N, x_1'..x_N', T)."""
    return jnp.concatenate([jnp.reshape(y0, (-1,)), jnp.atleast_1d(period)])


def unpack(u: Float[Array, " 2n+1"]) -> tuple[State, Float[Array, ""]]:
    """Inverse of `pack`."""
    return jnp.reshape(u[:-1], (2, -1)), u[-1]


def _orbit_engine(engine: AbstractEngine | None) -> AbstractEngine:
    return Smoothed().for_orbits() if engine is None else engine


class Shooting(AbstractOrbitMethod):
    """Single shooting (Seydel, *Practical Bifurcation and Stability Analysis*, 3rd
    ed. (2010), Sect. 7.1) on an engine: the unknowns are the state at t = 0 and
    the period, u = (x_1..x_N, x_1'..x_N', T); the residual is the engine's flow over
    one period minus the start, phi_T(y0) - y0, and the phase condition
    x_n'(0) = 0 (n = `phase_oscillator`: the orbit starts at a turning point of n,
    a Poincare section crossed by every stick-slip and every small Hopf cycle in
    which n vibrates). The Jacobian and the monodromy matrix come from forward-mode
    differentiation through the flow (`jax.jacfwd`): on the exact engine through
    every switch, which applies its saltation matrix (Leine and Nijmeijer,
    *Dynamics and Bifurcations of Non-Smooth Mechanical Systems*, 2004, Sect. 7.1).

    **Arguments:**

    - `engine`: the engine whose flow is shot, at its own solver and tolerances:
        give `engine.for_orbits()` (Tsit5 at rtol 1e-10, atol 1e-12 for
        `Smoothed`, 1e-12 for `Exact`), as accurate as the Floquet multipliers
        need. `Smoothed().for_orbits()` (eps = 1e-3) by default.
    - `newton_tol`: Newton's tolerance (optimistix, rtol = atol) on state and period.
    - `newton_steps`: Newton's iteration budget.
    - `root_finder`: "newton" (optimistix's Newton, fast near the orbit) or
        "levenberg-marquardt" (optimistix's Levenberg-Marquardt on the same
        residual: a damped method that converges from the rougher guesses of a
        simulated chain; More, *The Levenberg-Marquardt algorithm* (1978)).
    - `damped_steps`: where Newton's method (`root_finder` "newton") fails, the budget of the damped Newton
        method tried from the same guess (steps shortened by Armijo backtracking on
        the squared residual; Dennis and Schnabel 1996, Sect. 6.3), finished by
        Newton's method: near an orbit with multipliers close to +1 (weakly coupled
        oscillators' phases) a full step from a rough guess leaves the orbit's
        neighbourhood. 0 for none.
    - `n_samples`: samples of one period from which amplitudes and stick are read.
    - `phase_oscillator`: the oscillator n of the phase condition (0-based); choose
        one that vibrates.

    **Raises:**

    `ValidationError` naming the field for a non-positive tolerance or count, an
    unknown root finder, a negative phase oscillator, or an engine whose flow is
    too loose for an orbit (rtol > 1e-6) or differentiated in reverse mode.
    """

    engine: AbstractEngine = eqx.field(default=None, converter=_orbit_engine)
    newton_tol: float = eqx.field(static=True, default=1e-9)
    newton_steps: int = eqx.field(static=True, default=40)
    root_finder: str = eqx.field(static=True, default="newton")
    damped_steps: int = eqx.field(static=True, default=120)
    n_samples: int = eqx.field(static=True, default=4096)
    phase_oscillator: int = eqx.field(static=True, default=0)

    def __check_init__(self):
        if not isinstance(self.engine, AbstractEngine):
            raise ValidationError(f"Shooting.engine must be an engine (Smoothed or Exact), "
                                  f"got {type(self.engine).__name__}")
        rtol = self.engine.options.rtol
        if not rtol <= LOOSEST_RTOL:
            raise ValidationError(
                f"Shooting.engine: its flow's rtol {rtol:g} is too loose for a periodic "
                f"orbit (at most {LOOSEST_RTOL:g}); give engine.for_orbits()")
        if getattr(self.engine.options, "adjoint", "forward") != "forward":
            raise ValidationError("Shooting.engine: its adjoint must be 'forward': Newton's "
                                  "method and the monodromy matrix use forward mode")
        if self.phase_oscillator < 0:
            raise ValidationError(f"Shooting.phase_oscillator must be >= 0, got "
                                  f"{self.phase_oscillator!r}")
        if self.root_finder not in ROOT_FINDERS:
            raise ValidationError(f"Shooting.root_finder must be one of {ROOT_FINDERS}, got "
                                  f"{self.root_finder!r}")
        for name in ("newton_tol", "newton_steps", "n_samples"):
            if not getattr(self, name) > 0:
                raise ValidationError(f"Shooting.{name} must be > 0, got "
                                      f"{getattr(self, name)!r}")
        if not self.damped_steps >= 0:
            raise ValidationError(f"Shooting.damped_steps must be >= 0, got "
                                  f"{self.damped_steps!r}")

    @classmethod
    def from_simulations(cls, engine: AbstractEngine, **fields) -> "Shooting":
        """Shooting on `engine`'s model, started from its simulations: the engine
        made `for_orbits`, with the root finder that converges from a simulated
        state on it (`AbstractEngine.orbit_root_finder`), and `fields`."""
        return cls(engine.for_orbits(), **({"root_finder": engine.orbit_root_finder}
                                           | fields))

    def unknowns(self, params: ChainParams, y0: State, period) -> Float[Array, " 2n+1"]:
        """The unknowns of a checked guess, the phase oscillator's velocity set to 0.

        **Raises:** `ValidationError` for a guess of the wrong shape or a phase
        oscillator outside the chain."""
        return self.pack(phased_guess(self, params, y0), guess_period(params, period))

    def pack(self, y0: State, period) -> Float[Array, " 2n+1"]:
        return pack(y0, period)

    def orbit(self, u: Float[Array, " 2n+1"]) -> tuple[State, Float[Array, ""]]:
        return unpack(u)

    def residual(self, u: Float[Array, " 2n+1"], params: ChainParams) -> Float[Array, " 2n+1"]:
        """phi_T(y0) - y0 and the phase condition x_n'(0) (for a forced chain the
        force's period, `closing_condition`), shape (2 n_osc + 1,)."""
        y0, period = self.orbit(u)
        y1 = self.engine.flow(params, y0, period)
        return jnp.concatenate([jnp.reshape(y1 - y0, (-1,)), closing_condition(
            params, y0[1, self.phase_oscillator], period)])

    def monodromy(self, params: ChainParams, y0: State, period) -> Float[Array, "2n 2n"]:
        """The monodromy matrix d phi_T(y0) / d y0, by forward-mode differentiation
        through the engine's flow, ordered as `jacobian`, shape (2 n_osc, 2 n_osc)."""
        def end(z):
            return jnp.reshape(self.engine.flow(params, jnp.reshape(z, (2, -1)), period),
                               (-1,))
        return jax.jacfwd(end)(jnp.reshape(y0, (-1,)))

    def multipliers(self, params: ChainParams, u):
        y0, period = self.orbit(u)
        return deflated_multipliers(self.monodromy(params, y0, period),
                                    flow_direction(self.engine, params, y0))

    def describe(self, u: Float[Array, " 2n+1"], params: ChainParams) -> PeriodicOrbit:
        y0, period = self.orbit(u)
        ys, log_det = self.engine.orbit_samples(params, y0, period, self.n_samples)
        residual = jnp.max(jnp.abs(self.residual(u, params)))
        return orbit_record(params, y0, period, ys, self.engine.on_halc(params, ys),
                            self.monodromy(params, y0, period),
                            flow_direction(self.engine, params, y0),
                            self.engine.options.rtol, log_det, residual,
                            residual <= 1e3 * self.newton_tol)

    def samples(self, params: ChainParams, u, ts) -> Array:
        y0, _ = self.orbit(u)
        return self.engine.flow(params, y0, ts)

    def solve(self, params: ChainParams, u0):
        u, ok = _root(self, params, u0)
        if not bool(ok) and self.damped_steps and self.root_finder == "newton":
            # it may stop at a minimum of the residual that is not a root, or short of
            # its tolerance: Newton's method from where it stopped decides
            u, ok = _root(self, params, _damped_root(self, params, u0)[0])
        return u, ok

    def with_phase_oscillator(self, n: int) -> "Shooting":
        return dataclasses.replace(self, phase_oscillator=n)  # a static field

    def refine(self, factor: float) -> "Shooting":
        """Shooting with the flow's tolerances divided by `factor`."""
        options = self.engine.options
        return eqx.tree_at(lambda m: m.engine, self, self.engine.for_orbits(
            options.rtol / factor, options.atol / factor))


@checks_as_nan
@eqx.filter_jit
def _root(method: Shooting, params, u0):
    tol = method.newton_tol
    if method.root_finder == "newton":
        sol = optx.root_find(lambda u, p: method.residual(u, p),
                             optx.Newton(rtol=tol, atol=tol), u0, params,
                             max_steps=method.newton_steps, throw=False)
    else:  # forward-mode Jacobian: the flow is differentiated in forward mode
        sol = optx.least_squares(lambda u, p: method.residual(u, p),
                                 optx.LevenbergMarquardt(rtol=tol, atol=tol), u0, params,
                                 options={"jac": "fwd"}, max_steps=5 * method.newton_steps,
                                 throw=False)
    return sol.value, sol.result == optx.RESULTS.successful


@checks_as_nan
@eqx.filter_jit
def _damped_root(method: Shooting, params, u0):
    """`damped_newton` within the method's damped-step budget."""
    return damped_newton(method, params, u0, method.damped_steps)
