"""The one branch-following driver (`follow_branch`) on the single oscillator,
against an independent reference: a subcritical Hopf point in closed form, where
the branch of cycles shrinks onto steady sliding and the driver cuts it."""

import dataclasses

import numpy as np
import pytest

import jaxchain as jc


@pytest.mark.numerics
def test_followed_down_the_branch_ends_at_the_hopf_point_in_closed_form():
    """From a cycle 0.02 above the subcritical Hopf point, followed down in v_d, the
    cycles shrink onto steady sliding: the driver locates a "Hopf" bifurcation,
    cuts the branch there (stop "hopf"; beyond lie the same cycles half a period on)
    and keeps only points above it. Its v_d agrees with the closed form (eq. (5)
    linearized, `hopf_vd_analytic`) to 1e-6: the bisection resolves arclength,
    mostly amplitude there, along which v_d changes only quadratically."""
    params = jc.ChainParams(n_osc=1)
    method = jc.Shooting()
    start = jc.hopf_cycle(params, offset=0.02, method=method)
    followed = jc.follow_branch(start, method, jc.ContinuationOptions(
        ds=0.01, ds_max=0.1, p_min=1.0, p_max=2.5, max_points=40), directions=(-1,))
    hopf = float(jc.hopf_vd_analytic(params))
    assert followed.stops == {"end": "hopf"}
    (point,) = [b for b in followed.bifurcations if b.kind == "Hopf"]
    assert abs(point.p - hopf) < 1e-6
    assert np.all(followed.p > hopf) and followed.p[0] == float(start.params.v_d)
    # the amplitudes shrink towards the Hopf point, and every kept point converged
    assert np.all(np.diff(followed.amplitudes[:, 0]) < 0)
    assert np.all(followed.trivial_multiplier_error < 1e-6)


def test_a_stored_branch_is_read_back_for_equal_settings_only(tmp_path):
    """With `store`, the branch is written when done and a second call with equal
    settings reads it back: the same arrays, bifurcations and stops, bit for bit,
    without the continuations' pieces (documented: a branch read back has none). A
    call with another budget, another start or a damaged file computes again."""
    params = jc.ChainParams(n_osc=1)
    method = jc.Shooting()
    start = jc.hopf_cycle(params, offset=0.05, method=method)
    options = jc.ContinuationOptions(ds=0.02, ds_max=0.1, p_min=1.0, p_max=2.5, max_points=2)
    path = tmp_path / "branch.nc"
    first = jc.follow_branch(start, method, options, directions=(1,), store=path)
    assert first.pieces and path.exists()
    again = jc.follow_branch(start, method, options, directions=(1,), store=path)
    assert not again.pieces
    for name in ("p", "u", "energy", "period", "n_halc", "stable", "amplitudes",
                 "critical_multiplier_abs", "trivial_multiplier_error"):
        assert np.array_equal(getattr(again, name), getattr(first, name)), name
    assert again.bifurcations == first.bifurcations and again.stops == first.stops
    longer = dataclasses.replace(options, max_points=3)
    assert jc.follow_branch(start, method, longer, directions=(1,), store=path).pieces
    other = jc.hopf_cycle(params, offset=0.06, method=method)
    assert jc.follow_branch(other, method, longer, directions=(1,), store=path).pieces
    path.write_bytes(b"not netCDF")
    assert jc.follow_branch(other, method, longer, directions=(1,), store=path).pieces
