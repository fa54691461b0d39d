"""A harmonic force on the chain: per-oscillator amplitude and phase at one
frequency, and the engine-order pattern of a bladed disk. With a forcing, eq. (5)
is no longer autonomous: its periodic orbits have the forcing's period."""

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .._checks import check_count
from .._errors import ValidationError
from .friction import as_parameter, check_values


class Forcing(eqx.Module):
    """The harmonic force f_n(t) = amplitude_n cos(frequency t + phase_n) on each
    oscillator n, added to the right-hand side of eq. (5):

        m_n x_n'' = -2 xi_n x_n' - k_n x_n - (coupling)_n + (P_n/P) F(x_n' - v_d)
                    + f_n(t).

    Dimensionless as eq. (5): the amplitude in units of the normal load P, the
    frequency in units of omega_n (time in units of 1/omega_n, eq. (4)); a phase in
    radians. A travelling-wave excitation of engine order r on a ring (the bladed
    disk's) is `Forcing.engine_order`.

    **Arguments:**

    - `amplitude`: the force amplitude (>= 0), shape () or (n_osc,).
    - `frequency`: the forcing frequency Omega (> 0), shape (); the forced orbits'
        period is 2 pi / Omega.
    - `phase`: the phase of each oscillator's force (radians), shape () or (n_osc,);
        0 by default.

    Array fields, so that a new frequency does not recompile and results are
    differentiable in each; the chain (`ChainParams.forcing`) checks their shapes
    against n_osc.

    **Raises:**

    `ValidationError` naming the field for a negative or non-finite amplitude, a
    frequency <= 0, a non-finite phase or a frequency that is not a scalar.
    """

    amplitude: ArrayLike = eqx.field(converter=as_parameter)
    frequency: ArrayLike = eqx.field(converter=as_parameter)
    phase: ArrayLike = eqx.field(converter=as_parameter, default=0.0)

    def __check_init__(self):
        check_values("Forcing", {"amplitude": self.amplitude, "frequency": self.frequency,
                                 "phase": self.phase},
                     {"amplitude": (lambda a: a >= 0, ">= 0"),
                      "frequency": (lambda a: a > 0, "> 0")})
        if np.ndim(self.frequency) != 0:
            raise ValidationError(f"Forcing.frequency must have shape (), got "
                                  f"{np.shape(self.frequency)}")

    @classmethod
    def engine_order(cls, n_osc: int, order: int, amplitude, frequency) -> "Forcing":
        """The travelling wave of engine order r on a ring of N oscillators (a bladed
        disk's excitation): equal amplitudes, phase_n = 2 pi r n / N (n = 0..N-1).

        **Raises:** `ValidationError` for n_osc < 1, a negative order or a bad
        amplitude or frequency."""
        check_count("n_osc", n_osc)
        check_count("order", order, 0)
        phase = 2 * np.pi * order * np.arange(n_osc) / n_osc
        return cls(amplitude=amplitude, frequency=frequency, phase=phase)

    @property
    def period(self) -> Float[Array, ""]:
        """2 pi / Omega, the period of the force (and of a forced orbit)."""
        return 2 * jnp.pi / self.frequency

    def force(self, t) -> Float[Array, " n_osc"]:
        """f_n(t) = amplitude_n cos(frequency t + phase_n), shape () or (n_osc,)."""
        return self.amplitude * jnp.cos(self.frequency * t + self.phase)
