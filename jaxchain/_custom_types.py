"""Shape aliases shared across jaxchain (jaxtyping)."""

from jaxtyping import Array, ArrayLike, Bool, Float, Int

#: State of one chain: row 0 holds the displacements x_n, row 1 the velocities x_n'.
State = Float[Array, "2 n_osc"]
#: Per-oscillator quantity.
PerOsc = Float[Array, "n_osc"]
#: Mask over the oscillators.
OscMask = Bool[Array, "n_osc"]
Scalar = Float[Array, ""]
ScalarLike = Float[ArrayLike, ""]
IntScalar = Int[Array, ""]
