"""Options of a simulation run: horizon, tolerances and how observables are sampled."""

import equinox as eqx

from .horizon import AbstractHorizon, positive
from .solver.controller import CONTROLLERS
from .._checks import check_count
from .._errors import ValidationError


class SimulationOptions(AbstractHorizon):
    """How long to integrate, how accurately, and how to observe: the horizon of
    `AbstractHorizon` with the smoothed engine's tolerances and sampling.

    All fields but the tolerances are static: changing one recompiles. `rtol` and
    `atol` may be given as JAX arrays, so that a sweep over tolerances compiles
    once (Python floats are static like the other fields). Times are dimensionless, in units
    of 1/omega_n (eq. (4) of the paper).

    **Arguments:**

    - `t_end`: final time. The paper's default is 15000.
    - `transient`: observables are taken over [transient, t_end]. The paper's
        default is 10000 (Section 3.2).
    - `rtol`, `atol`: tolerances of the step-size controller. The defaults, 3e-5
        and 3e-7, are the loosest at which the cross-check holds (every n_HALC
        agrees with the non-smooth reference; at 1e-4 the states near the fold of
        existence, v_d = 1.75, decay): the integration error is then below the
        error of the smoothing at the default eps = 1e-3 (documentation, "Performance").
    - `controller`: the step-size controller, "pi" (`PIController`, the default)
        or "diffrax" (diffrax's `PIDController` as an integral controller, the
        controller jaxchain used first); see `CONTROLLERS`.
    - `sample_dt`: spacing of the dense-output samples from which the extrema are
        taken. An extremum of a smooth slip phase is missed by at most
        |x''| sample_dt^2 / 8 ~ A sample_dt^2 / 8, a relative 3e-4 for the default
        0.05, below the 1e-3 resolution asked of the amplitudes.
    - `chunk_length`: the run is integrated in chunks of about this length; the
        samples of one chunk are reduced before the next starts, so memory is fixed
        by `chunk_length / sample_dt`, never by `t_end`.
    - `max_steps`: step budget of one chunk.
    - `dtmin`: a run that spends a chunk's `max_steps` on steps shorter than this
        on average fails with `Status.step_size_collapsed` rather than
        `Status.max_steps_reached`: its steps have stopped advancing t (at t = 15000
        a float64 resolves 2e-12). It does not limit the step-size controller,
        whose steps are those of diffrax's `PIDController` alone.

    Which oscillators are on the HALC is not an option: it is the one definition of
    `sticks`, shared with shooting and the non-smooth reference.

    **Raises:**

    `ValidationError` naming the field for t_end <= 0, transient outside [0, t_end),
    non-positive or non-finite tolerances, sample_dt, chunk_length, max_steps or
    dtmin, and a controller not in `CONTROLLERS`.
    """

    t_end: float = eqx.field(static=True, default=15000.0)
    transient: float = eqx.field(static=True, default=10000.0)
    rtol: float = 3e-5
    atol: float = 3e-7
    controller: str = eqx.field(static=True, default="pi")
    sample_dt: float = eqx.field(static=True, default=0.05)
    chunk_length: float = eqx.field(static=True, default=250.0)
    max_steps: int = eqx.field(static=True, default=200_000)
    dtmin: float = eqx.field(static=True, default=1e-10)

    def __check_init__(self):
        for name in ("rtol", "atol", "sample_dt", "max_steps", "dtmin"):
            value = getattr(self, name)
            if not positive(value):
                raise ValidationError(f"SimulationOptions.{name} must be a finite number > 0, "
                                      f"got {value!r}")
        if self.controller not in CONTROLLERS:
            raise ValidationError(f"SimulationOptions.controller must be one of "
                                  f"{', '.join(CONTROLLERS)}, got {self.controller!r}")
        check_count("SimulationOptions.max_steps", self.max_steps)
        self.check_horizon()
