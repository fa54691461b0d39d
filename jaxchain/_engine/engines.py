"""The engine as a value: what integrates one trajectory of eq. (5), chosen where a
solver was chosen before. Two concrete engines behind one interface: `Smoothed`
(friction smoothed by tanh(v_rel/eps), integrated by diffrax) and `Exact` (the
stick/slip switch model of Leine et al. (1998), event by event). Every layer above
(`simulate`, `run_lanes`, `ensemble`) takes either without knowing which."""

import abc
from typing import ClassVar

import diffrax
import equinox as eqx
import numpy as np
from jaxtyping import ArrayLike

from .checks import as_solver, check_options
from .exact.options import NonsmoothOptions
from .exact.solve import run_exact
from .horizon import AbstractHorizon
from .observables import Observables
from .options import SimulationOptions, check_stick_band, follow_eps
from .smoothed import run, run_observers
from .status import Status, failure_hint
from .solver.registry import DEFAULT_SOLVER, SOLVERS
from .._physics.custom_types import State
from .._physics.forces import DEFAULT_EPS
from .._physics.friction import as_parameter, check_values
from .._physics.params import ChainParams
from .._errors import ValidationError


class AbstractEngine(eqx.Module):
    """An engine: how one trajectory of eq. (5) is integrated and observed. It holds
    its own settings (solver, tolerances, horizon) and is passed as a value wherever
    a trajectory is run; `run` is pure and traceable, so that `run_lanes` can map it
    over lanes, on a queue of CPU devices or vmapped on a GPU.

    Subclasses: `Smoothed` and `Exact`. Name one by a string with its defaults
    (`as_engine`): `engine="smoothed"` (the default) or `engine="exact"`.
    """

    name: ClassVar[str]
    options: eqx.AbstractVar[AbstractHorizon]

    @abc.abstractmethod
    def run(self, params: ChainParams, y0: State, progress: bool = False) -> Observables:
        """One trajectory from the state `y0` (shape (2, n_osc)): its `Observables`
        over [transient, t_end]. Pure and traceable: no checks, no exceptions; a
        failure is its `status`. With `progress` (static), each chunk ticks the
        active progress bar."""

    @abc.abstractmethod
    def n_chunks(self) -> int:
        """The chunks of one run: the ticks of its progress bar."""

    def failure_hint(self, status: int, params: ChainParams) -> str:
        """What to do about a run that ended with `status` (`Status`)."""
        return Status(status).message

    @abc.abstractmethod
    def attributes(self) -> dict:
        """The engine and every setting that shapes its results, as dataset
        attributes and store keys (strings and numbers)."""

    def run_observers(self, params: ChainParams, y0: State, observers: tuple,
                      progress: bool = False) -> dict:
        """One trajectory with the given observers only (`observe`); the smoothed
        engine's. Raises `ValidationError` where the engine cannot."""
        raise ValidationError(f"the {self.name} engine observes amplitudes, energy and "
                              "the HALC only (Extrema): run other observers with "
                              "engine='smoothed'")

    # --- behaviour the studies ask of an engine ---

    @abc.abstractmethod
    def describe(self) -> str:
        """The model this engine integrates, in one line for a result's summary
        ("the smoothed model, eps = 1e-05")."""

    @abc.abstractmethod
    def can_observe(self, observers: tuple) -> bool:
        """Whether `run_observers` runs `observers` (the smoothed engine runs any);
        where not, the engine observes its `Observables` only."""

    @abc.abstractmethod
    def with_parameter(self, name: str, value) -> "AbstractEngine":
        """This engine with its parameter `name` (one of the engine's own, such as
        the smoothed engine's "eps") at `value`, every other setting kept, its
        resolved tolerances included (`eqx.tree_at`: a swept value does not
        recompile).

        **Raises:**

        `ValidationError` in one line where the engine has no such parameter.
        """

    @abc.abstractmethod
    def as_smoothed(self, what: str) -> "Smoothed":
        """This engine as the smoothed one, for `what`, which integrates the smoothed
        model with its solver, options and eps.

        **Raises:**

        `ValidationError` in one line naming `what` where the engine smooths
        nothing (the exact one).
        """

    @abc.abstractmethod
    def states_at(self, params: ChainParams, y0: State, times) -> tuple:
        """The states at `times` from `y0`: the flow map that a multiple-shooting
        window integrates (`identify`). Pure and traceable (no checks, no
        exceptions), and differentiable in forward mode (`jax.jacfwd`) in `params`,
        `y0` and the engine's array leaves (the smoothed engine's eps: a new eps
        does not recompile). At the engine's tolerances and budgets; its horizon
        (t_end, transient) does not apply.

        **Arguments:**

        - `params`: the chain.
        - `y0`: the state at t = 0, shape (2, n_osc).
        - `times`: increasing times from 0, shape (K,), dimensionless (eq. (4)).

        **Returns:**

        (states, ok): the states at `times`, shape (K, 2, n_osc), and whether the
        integration succeeded (bool, shape ()). The smoothed engine's `max_steps`
        bounds the whole span (one diffrax solve, `diffrax.ForwardMode`); the exact
        engine's, each interval between successive `times` (one chunk each,
        `nonsmooth_flow`).
        """


class Smoothed(AbstractEngine):
    """The smoothed engine: eq. (5) with the friction law's sign(v_rel) smoothed as
    tanh(v_rel/eps) (eq. (1) of the paper with eq. (7)), integrated by a diffrax
    solver in chunks with dense output observed as it goes (`simulate`). The
    smoothing is the engine's, not the chain's: `ChainParams` holds physics only.

    **Arguments:**

    - `solver`: a diffrax solver or the name of one (`SOLVERS`); `Ros34PW2()` by
        default (`DEFAULT_SOLVER`). "auto" (chosen from eps) is resolved by
        `as_engine`, which sees the chain.
    - `options`: `SimulationOptions` (horizon, tolerances, sampling). Tolerances
        left None follow eps (`follow_eps`: rtol = min(3e-5, eps/30), atol =
        min(3e-7, eps/3000)); the engine holds them resolved.
    - `eps`: the smoothing velocity of tanh(v_rel/eps) (> 0), shape (),
        dimensionless (a fraction of x_0 omega_n, eqs. (4)-(6)); `DEFAULT_EPS` =
        1e-3 by default. An array leaf: a new eps does not recompile, and
        derivatives with respect to it flow through a run.

    **Raises:**

    `ValidationError` for an unknown solver name, eps <= 0 (or not finite), or
    tolerances given that cannot resolve the stick band |v_rel| <= 3 eps
    (`check_stick_band`: rtol + atol > 100 eps); `TypeError` for options of
    another kind.
    """

    name: ClassVar[str] = "smoothed"
    solver: diffrax.AbstractSolver
    options: SimulationOptions
    eps: ArrayLike = eqx.field(converter=as_parameter)

    def __init__(self, solver: diffrax.AbstractSolver | str = DEFAULT_SOLVER,
                 options: SimulationOptions = SimulationOptions(), eps=DEFAULT_EPS):
        self.solver = as_solver(solver)
        self.options = follow_eps(check_options(options), eps)
        self.eps = eps

    def __check_init__(self):
        check_values("Smoothed", {"eps": self.eps}, {"eps": (lambda a: a > 0, "> 0")})
        if np.ndim(self.eps) != 0:
            raise ValidationError(f"Smoothed.eps must be one number (shape ()), got shape "
                                  f"{np.shape(self.eps)}")
        check_stick_band(self.options, self.eps)

    def run(self, params: ChainParams, y0: State, progress: bool = False) -> Observables:
        return run(params, self.eps, y0, self.solver, self.options, progress)

    def run_observers(self, params: ChainParams, y0: State, observers: tuple,
                      progress: bool = False) -> dict:
        return run_observers(params, self.eps, y0, self.solver, self.options, observers,
                             progress)

    def n_chunks(self) -> int:
        return self.options.n_chunks()

    def failure_hint(self, status: int, params: ChainParams) -> str:
        return failure_hint(status, params, self.solver, self.options, self.eps)

    def attributes(self) -> dict:
        return {"engine": self.name, "eps": float(self.eps),
                "solver": type(self.solver).__name__,
                "rtol": self.options.rtol, "atol": self.options.atol}

    # --- behaviour the studies ask of an engine ---

    def describe(self) -> str:
        return f"the smoothed model, eps = {float(self.eps):g}"

    def can_observe(self, observers: tuple) -> bool:
        return True

    def with_parameter(self, name: str, value) -> "Smoothed":
        if name != "eps":
            raise ValidationError(f"{name}: the smoothed engine's only parameter is eps "
                                  "(the chain's are fields of ChainParams)")
        return eqx.tree_at(lambda e: e.eps, self, value)

    def as_smoothed(self, what: str) -> "Smoothed":
        return self

    def states_at(self, params: ChainParams, y0: State, times) -> tuple:
        from .smoothed import terms
        from .solver.controller import step_size_controller
        from .._physics.model import Model

        sol = diffrax.diffeqsolve(
            terms(self.solver), self.solver, 0.0, times[-1], None, y0,
            Model(params, self.eps), saveat=diffrax.SaveAt(ts=times),
            stepsize_controller=step_size_controller(self.options),
            adjoint=diffrax.ForwardMode(), max_steps=self.options.max_steps, throw=False)
        return sol.ys, diffrax.is_successful(sol.result)


class Exact(AbstractEngine):
    """The exact engine: the stick/slip switch model of Leine et al. (1998),
    Nonlinear Dynamics 16, 41-54, without its stick band (stick is exact, x_n' =
    v_d): smooth slip segments integrated by diffrax, switches located as events
    (`simulate_nonsmooth`). No eps: nothing is smoothed. Its observables
    are those of the smoothed engine, in the same layout; an oscillator is on the
    HALC when it sticks during the window.

    **Arguments:**

    - `options`: `NonsmoothOptions` (horizon, tolerances, event budgets).

    **Raises:**

    `TypeError` for options of another kind.
    """

    name: ClassVar[str] = "exact"
    options: NonsmoothOptions = NonsmoothOptions()

    def __check_init__(self):
        if not isinstance(self.options, NonsmoothOptions):
            raise TypeError(f"Exact takes NonsmoothOptions, got "
                            f"{type(self.options).__name__}")

    def run(self, params: ChainParams, y0: State, progress: bool = False) -> Observables:
        return run_exact(params, y0, self.options, progress)

    def n_chunks(self) -> int:
        return self.options.n_chunks(halves=True)  # the window's halves are chunked apart

    def attributes(self) -> dict:
        return {"engine": self.name, "solver": self.options.solver,
                "rtol": self.options.rtol, "atol": self.options.atol,
                "root_tol": self.options.root_tol}

    # --- behaviour the studies ask of an engine ---

    def describe(self) -> str:
        return "the exact stick/slip model"

    def can_observe(self, observers: tuple) -> bool:
        return False

    def with_parameter(self, name: str, value) -> "Exact":
        raise ValidationError(f"{name}: the exact engine has no {name} (it does not smooth "
                              f"the friction law); give {name} to a jaxchain.Smoothed engine")

    def as_smoothed(self, what: str) -> "Smoothed":
        raise ValidationError(f"engine: {what} integrates the smoothed model; the "
                              f"{self.name} engine has no eps to smooth it with: give "
                              "engine='smoothed' or a jaxchain.Smoothed")

    def states_at(self, params: ChainParams, y0: State, times) -> tuple:
        from .exact.solve import nonsmooth_flow

        ys, status = nonsmooth_flow(params, y0, times, self.options)
        return ys, status == Status.ok


#: The engines by name, each with its defaults.
ENGINES = {"smoothed": Smoothed, "exact": Exact}


def as_engine(engine: AbstractEngine | str = "smoothed",
              solver: diffrax.AbstractSolver | str | None = None,
              options: AbstractHorizon | None = None,
              params: ChainParams | None = None, eps=None) -> AbstractEngine:
    """The engine value that `engine` names, with `solver`, `options` and `eps`
    where given.

    **Arguments:**

    - `engine`: "smoothed", "exact" (`ENGINES`), or an engine value (returned as is;
        `solver` and `options` must then be None).
    - `solver`: the smoothed engine's solver (a diffrax solver, a name of `SOLVERS`,
        or "auto", chosen from eps by `auto_solver` with `params`).
    - `options`: `SimulationOptions` for the smoothed engine; for the exact one
        `NonsmoothOptions`, or `SimulationOptions` whose horizon (t_end, transient,
        chunk_length) it takes with its own tolerances.
    - `params`: the chain, for `solver="auto"`.
    - `eps`: the smoothed engine's smoothing velocity (`Smoothed.eps`);
        `DEFAULT_EPS` when None.

    **Returns:**

    An `AbstractEngine`.

    **Raises:**

    `ValidationError` for an unknown engine name, a solver or eps given to the exact
    engine, or settings given beside an engine value; `TypeError` for options of another kind.
    """
    if isinstance(engine, AbstractEngine):
        if solver is not None or options is not None or eps is not None:
            raise ValidationError("give the solver, options and eps inside the engine "
                                  "value, not beside it")
        return engine
    if engine in ("queue", "vmap"):
        raise ValidationError(f"engine={engine!r}: engine names the model now ('smoothed' or "
                              f"'exact'); how lanes are run is schedule={engine!r}")
    if engine not in ENGINES:
        raise ValidationError(f"engine must be one of {sorted(ENGINES)} or an engine value, "
                              f"got {engine!r}")
    if engine == "smoothed":
        eps = DEFAULT_EPS if eps is None else eps
        solver = SOLVERS[DEFAULT_SOLVER]() if solver is None else as_solver(
            solver, params=params, eps=eps)
        return Smoothed(solver, SimulationOptions() if options is None else options, eps)
    if eps is not None:
        raise ValidationError("eps: the exact engine has no eps (it does not smooth the "
                              "friction law); give eps to engine='smoothed'")
    if solver is not None:
        raise ValidationError("the exact engine takes no solver: it integrates its slip "
                              "segments itself (NonsmoothOptions sets its tolerances)")
    if isinstance(options, SimulationOptions):
        options = NonsmoothOptions(t_end=options.t_end, transient=options.transient,
                                   chunk_length=options.chunk_length)
    return Exact(NonsmoothOptions() if options is None else options)
