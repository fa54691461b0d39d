"""A followed branch of the snake (`follow_branch`) as the snake stores it: the
driver's stored form (`followed_dataset`) with the number of sites its start excites,
the form of the stores of earlier releases, which still read back."""

from __future__ import annotations

from typing import TYPE_CHECKING

from ..._bifurcation.branch_file import followed_dataset
from ..._bifurcation.branches import FollowedBranch
from ..._bifurcation.continuation import ContinuationOptions

if TYPE_CHECKING:  # heavy: imported where they are used
    import xarray as xr


#: Continuation of each branch: far enough each way (150 points) to pass its folds.
SNAKE_CONTINUATION = ContinuationOptions(ds=0.02, ds_max=0.1, p_min=1.0, p_max=2.2,
                                         max_points=150)

#: Part of the key of stored branches, the revision of how a branch is followed
#: and started (`follow_branch`, `start_orbits`): raised whenever it changes, so
#: that a resumed run recomputes the branches of an older revision. Revision 7 is
#: the one whose stores the ring of 8 and the ring of 20 keep.
BRANCH_METHOD = 7


def branch_dataset(branch: FollowedBranch, k: int) -> xr.Dataset:
    """The stored form of a followed branch of start `k` (`followed_dataset`, with
    the attribute `excited`: k excited oscillators)."""
    return followed_dataset(branch, excited=k)
