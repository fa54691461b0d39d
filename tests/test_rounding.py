"""The canary of CI's second rounding (.ci/run): the tests marked `numerics` run twice,
the second time with XLA generating code for another instruction set. That pass
proves something only if it computes different bits; this test records a digest of
a stick-slip run in the first pass and asserts, in the second, that the digest
differs. If a jaxlib ever ignores the flag of the second pass (as jaxlib 0.10 ignores
`--xla_cpu_enable_fast_math`), CI says so here instead of repeating the first pass.

.ci/run names the digest file in JAXCHAIN_ROUNDING_DIGEST and the pass in
JAXCHAIN_ROUNDING_PASS (`first` or `second`). Outside CI (neither set), the test
checks that one compiled program gives the same bits twice, which the comparisons
"bitwise only within one program" of the other tests rely on."""

import hashlib
import os
from pathlib import Path

import numpy as np
import pytest

import jaxchain as jc


def _digest() -> tuple[str, np.ndarray]:
    """SHA-256 of the final state of a stick-slip run of a ring of 4 with one
    excited oscillator (eq. (8)), about 4,400 steps: long enough that every
    difference of rounding in the step reaches the last bits of y_final."""
    params = jc.ChainParams(n_osc=4, v_d=1.5)
    y0 = jc.OutOfPhaseExcitation(jc.excited_block(4, 1))
    run = jc.simulate(params, y0, options=jc.SimulationOptions(t_end=200.0,
                                                                transient=100.0))
    y = np.asarray(run.y_final)
    return hashlib.sha256(y.tobytes()).hexdigest(), y


@pytest.mark.numerics
def test_second_rounding_changes_the_digest():
    digest, y = _digest()
    assert np.all(np.isfinite(y))
    path, which = os.environ.get("JAXCHAIN_ROUNDING_DIGEST"), os.environ.get(
        "JAXCHAIN_ROUNDING_PASS")
    if which == "first":
        Path(path).write_text(digest)
    elif which == "second":
        first = Path(path).read_text()
        assert digest != first, (
            "the second pass of .ci/run computed the same bits as the first: its "
            "XLA_FLAGS no longer change the rounding, so it proves nothing")
    else:
        assert _digest()[0] == digest
