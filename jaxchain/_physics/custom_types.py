"""Shape aliases shared across jaxchain (jaxtyping)."""

from jaxtyping import Array, Float

#: State of one chain: row 0 holds the displacements x_n, row 1 the velocities x_n'.
State = Float[Array, "2 n_osc"]
