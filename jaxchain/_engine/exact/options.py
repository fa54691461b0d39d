"""Options of a run of the exact engine, and those of the non-smooth reference."""

import equinox as eqx

from ..horizon import AbstractHorizon, positive
from ..options import check_tolerances
from ..._errors import ValidationError
from .stepping import SOLVERS


#: The tolerances of the non-smooth reference (`NonsmoothOptions.reference`): Tsit5
#: at rtol = atol = 1e-12, amplitudes within about 1e-9 of Dopri8 at 1e-13 on the
#: Fig. 4 scene (benchmarks/exact_engine.py).
REFERENCE_TOLERANCES = {"solver": "tsit5", "rtol": 1e-12, "atol": 1e-12}


class NonsmoothOptions(AbstractHorizon):
    """Horizon, tolerances and bookkeeping of a run of the exact engine (`Exact`):
    the horizon of `AbstractHorizon` with the event-driven
    run's tolerances and budgets. The defaults are the exact engine's, chosen by
    work-precision on the Fig. 4 scene: as fast as the smoothed engine at its
    defaults, its amplitudes within a few 1e-6 of the reference on periodic
    states. `NonsmoothOptions.reference` gives the reference's tolerances.

    All fields are static: changing one recompiles. Times are dimensionless, in units
    of 1/omega_n (eq. (4) of the paper).

    **Arguments:**

    - `t_end`: final time (the paper's 15000).
    - `transient`: the observables are taken over [transient, t_end] (the paper's
        10000), split into two halves of equal length to tell periodic from
        irregular states.
    - `rtol`, `atol`: tolerances of the smooth phases (diffrax `PIDController`),
        1e-7 by default; the reference's, 1e-12, make it about 1e-9 accurate.
    - `solver`: the Runge-Kutta pair of the smooth phases: "tsit5", "dopri5" (the
        default) or "dopri8".
    - `adjoint`: the mode of automatic differentiation the run is built for:
        "forward" (the default: `jax.jvp`, `jax.jacfwd`; plain loops) or "reverse"
        (`jax.grad`, `jax.vjp`; nested checkpointed loops whose memory is bounded
        however many steps and chunks a run takes). A run is computed the same
        either way. Reverse mode of a "forward" run raises a `RuntimeError` of
        one line that names this setting.
    - `root_tol`: absolute tolerance on event times of the bracketed root find
        (Chandrupatla's method) that locates them on the dense output.
    - `switch_tol`: at a switch, every oscillator whose guard (relative velocity or
        stick margin mu_st - |f|) lies within `switch_tol` of zero
        switches at that instant. This is how simultaneous and near-simultaneous
        switches are handled; see `Exact`.
    - `chunk_length`: the run advances in chunks of about this length (one
        progress tick each); every chunk end is a step end.
    - `max_steps`: step budget of one chunk.
    - `max_events`: budget of switch instants of one chunk; more means chattering.
    - `log_size`: the switch log gives the last `log_size` switches.
    - `held`: oscillators (0-based indices) held in the mode they start in: their
        guard is ignored, so a slipping one never sticks or reverses and slips on
        past v_rel = 0 with its friction force's sign (the smooth continuation of
        a slip phase, which `continue_past_sliding` follows through a sliding
        bifurcation). Empty by default: the switch model itself.

    **Raises:**

    `ValidationError` naming the field for t_end <= 0, transient outside [0, t_end),
    rtol or atol outside (0, 1), a tolerance, length or budget that is not a
    finite number > 0, an unknown
    solver or adjoint, or `held` not a tuple of indices >= 0.
    """

    t_end: float = eqx.field(static=True, default=15000.0)
    transient: float = eqx.field(static=True, default=10000.0)
    rtol: float = eqx.field(static=True, default=1e-7)
    atol: float = eqx.field(static=True, default=1e-7)
    solver: str = eqx.field(static=True, default="dopri5")
    adjoint: str = eqx.field(static=True, default="forward")
    root_tol: float = eqx.field(static=True, default=1e-13)
    switch_tol: float = eqx.field(static=True, default=1e-9)
    chunk_length: float = eqx.field(static=True, default=250.0)
    max_steps: int = eqx.field(static=True, default=100_000)
    max_events: int = eqx.field(static=True, default=100_000)
    log_size: int = eqx.field(static=True, default=1024)
    held: tuple[int, ...] = eqx.field(static=True, default=())

    @classmethod
    def reference(cls, **fields) -> "NonsmoothOptions":
        """The options of the non-smooth reference: `REFERENCE_TOLERANCES` (Tsit5 at
        rtol = atol = 1e-12), with any field given here (the horizon, budgets)."""
        return cls(**(REFERENCE_TOLERANCES | fields))

    def __check_init__(self):
        check_tolerances("NonsmoothOptions", self.rtol, self.atol)
        for name in ("root_tol", "switch_tol", "max_steps", "max_events", "log_size"):
            value = getattr(self, name)
            if not positive(value):
                raise ValidationError(f"NonsmoothOptions.{name} must be a finite number > 0, "
                                      f"got {value!r}")
        if not (isinstance(self.held, tuple) and all(isinstance(n, int) and n >= 0
                                                      for n in self.held)):
            raise ValidationError(f"NonsmoothOptions.held must be a tuple of oscillator "
                                  f"indices >= 0, got {self.held!r}")
        if self.adjoint not in ("forward", "reverse"):
            raise ValidationError(f"NonsmoothOptions.adjoint must be 'forward' or 'reverse', "
                                  f"got {self.adjoint!r}")
        if self.solver not in SOLVERS:
            raise ValidationError(f"NonsmoothOptions.solver must be one of "
                                  f"{', '.join(SOLVERS)}, got {self.solver!r}")
        self.check_horizon()
