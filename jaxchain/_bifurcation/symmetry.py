"""The symmetries that fix a state: its isotropy subgroup among the chain's
symmetries (on a homogeneous ring its rotations and reflections; Golubitsky,
Stewart and Schaeffer, *Singularities and Groups in Bifurcation Theory*, Vol. II
(1988), ch. XII)."""

import numpy as np

from .deflation import chain_symmetries
from .._physics.params import ChainParams


def isotropy(params: ChainParams, y, atol: float = 1e-12) -> np.ndarray:
    """The symmetries of the chain (`chain_symmetries`: on a homogeneous ring its
    rotations and reflections) that map the state y, shape (2, n_osc), onto itself
    within `atol`: its isotropy subgroup, shape (s, n_osc), the identity first. For
    eq. (8) on the ring, an odd block of excited oscillators is fixed by the
    reflection about its centre; an even block by no symmetry (its signs
    alternate). A state solved by shooting keeps its symmetry only to Newton's
    tolerance: pass an `atol` above it."""
    y = np.asarray(y)
    perms = np.asarray(chain_symmetries(params))
    fixed = perms[[np.allclose(y[:, p], y, rtol=0.0, atol=atol) for p in perms]]
    return fixed[np.argsort([not np.array_equal(p, np.arange(y.shape[1])) for p in fixed],
                            kind="stable")]
