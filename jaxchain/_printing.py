"""How a result prints: its values, not the shapes of its arrays."""

import equinox as eqx


def values_repr(result: eqx.Module) -> str:
    """`repr` of a result module with the values of its arrays (equinox's default
    `repr` prints shapes only, `f64[1]`), as NumPy prints them (long arrays
    summarised)."""
    return eqx.tree_pformat(result, short_arrays=False)
