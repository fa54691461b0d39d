"""Deflation (Farrell, Birkisson and Funke 2015) on the ring of three at v_d = 1.5,
where simulation from eq. (8) with one and with two excited oscillators ends on two
different stable states: repeated deflation from one start finds the state that
simulation finds from it, then further periodic orbits that are none of its
symmetric copies, each a periodic orbit of an independent integrator (scipy); the
snake's branches of the orbits deflation finds. All through public names: the
deflation operator's distance and the ring's symmetries, and the snake's deflation
provoked or spied on through its private functions, are test_snake.py's."""

import numpy as np
import jax.numpy as jnp
import pytest
import xarray as xr

import jaxchain as jc

from helpers import (RING_OF_THREE, SETTLED, SHOOTING_OF_THREE, copies_distance, packed,
                     scipy_return)

RING, SHOOTING = RING_OF_THREE, SHOOTING_OF_THREE
#: The starts settle within 1500 time units on three oscillators.
START = SETTLED


@pytest.fixture(scope="module")
def simulated(ring_of_three_states):
    """The states that simulation reaches from eq. (8) with k = 1 and 2 excited,
    refined by shooting: {k: PeriodicOrbit} (tests/conftest.py's, shared with the
    tests of the snake's deflation in test_snake.py)."""
    return ring_of_three_states


def eq8_start(k):
    """Eq. (8) with k excited and T = 2 pi, the phase oscillator's velocity 0."""
    y0 = jnp.asarray(jc.OutOfPhaseExcitation.eq8(jc.excited_block(3, k))(RING))
    return packed(y0.at[1, SHOOTING.phase_oscillator].set(0.0), 2 * np.pi)


def _orbit(u):
    return jc.periodic_orbit(RING, (jnp.reshape(u[:-1], (2, -1)), float(u[-1])), SHOOTING)


@pytest.mark.numerics
@pytest.mark.parametrize("scale", [0.0, 1e-6, 1e-4])
@pytest.mark.study
def test_repeated_deflation_from_one_start_finds_distinct_orbits(simulated, scale):
    """From eq. (8) with two excited (perturbed by a relative `scale`, with the phase
    condition kept), nothing known: first the two-site state that simulation
    reaches from that start (the same period to 1e-7, two solves at Newton's
    tolerance 1e-9), then, with it and all six
    of its copies under the ring's rotations and reflections deflated, from the
    same start, two more orbits: periodic for scipy to 1e-6, none a copy of
    another or of the states found before, and not stable (simulation does not
    show them)."""
    start = eq8_start(2)
    noise = np.random.default_rng(1).standard_normal(start.shape)
    start = (start * (1 + scale * noise)).at[3 + SHOOTING.phase_oscillator].set(0.0)
    problem = jc.cycle_problem(simulated[1], SHOOTING)
    found = jc.distinct_orbits(problem, start, count=3)
    assert len(found) == 3
    assert abs(float(found[0][-1]) - float(simulated[2].period)) < 1e-7  # two Newton solves
    assert copies_distance(packed(simulated[2].y0, simulated[2].period),
                           found[0]) < 1e-6
    for u in found[1:]:
        assert scipy_return(u) < 1e-6
        assert not bool(_orbit(u).stable)
    for i in range(3):
        for j in range(i):
            assert copies_distance(found[j], found[i]) > 1e-2


@pytest.mark.numerics
@pytest.mark.study
def test_deflating_the_state_of_a_start_leads_elsewhere(simulated):
    """Shooting from eq. (8) with one excited reaches the one-site state, as
    simulation does from there; with that state deflated (the other state,
    simulation's two-site one, not) the same start gives another orbit, periodic
    for scipy, that is no copy of the one-site state."""
    start = eq8_start(1)
    one = packed(simulated[1].y0, simulated[1].period)
    problem = jc.cycle_problem(simulated[1], SHOOTING)
    # Only the first orbit of each call is checked: it is the first solve, the same
    # whatever `count` (a free slot of the operator deflates nothing), and these counts
    # give the operator the two free slots of the solve that
    # test_repeated_deflation_from_one_start_finds_distinct_orbits compiled
    # (len(known) + count - 1 = 2) instead of two more compiled solves.
    plain = jc.distinct_orbits(problem, start, count=3)
    assert copies_distance(one, plain[0]) < 1e-6
    other = jc.distinct_orbits(problem, start, [one], count=2)[0]
    assert copies_distance(one, other) > 1e-2 and scipy_return(other) < 1e-6


@pytest.mark.study
def test_symmetries_of_the_ring_and_bad_arguments(simulated):
    """Clear errors for bad arguments (the ring's symmetries and the deflation
    operator's own, test_snake.py)."""
    problem = jc.cycle_problem(simulated[1], SHOOTING)
    with pytest.raises(ValueError, match="count"):
        jc.distinct_orbits(problem, problem.u0, count=0)
    with pytest.raises(ValueError, match="capacity"):
        jc.distinct_orbits(problem, problem.u0, count=2, capacity=0)
    with pytest.raises(ValueError, match="deflate"):
        jc.localized_branches(RING, (1,), deflate=-1)


@pytest.mark.study
def test_the_snake_follows_the_orbits_that_deflation_finds(tmp_path):
    """`localized_branches(deflate=2)` from eq. (8) with two excited: besides the
    branch of the simulated state, the branches of two further orbits at the start's
    v_d, each a periodic orbit for scipy and no symmetric copy of the others; all
    stored and read back."""
    kwargs = dict(continuation_options=jc.ContinuationOptions(
        ds=0.02, ds_max=0.05, p_min=1.45, p_max=1.55, max_points=3),
        start_options=START, simulation_check=False, deflate=2, out=tmp_path)
    found = jc.localized_branches(RING, (2,), **kwargs)
    labels = ["k=2", "k=2 deflated 1", "k=2 deflated 2"]
    assert list(found["datasets"]) == labels
    starts = []
    for label in labels:
        ds = found["datasets"][label]
        starts.append(ds["u"].values[int(np.argmin(np.abs(ds["v_d"].values - 1.5)))])
    for u in starts[1:]:
        assert scipy_return(u) < 1e-6
    for i in range(3):
        for j in range(i):
            assert copies_distance(starts[j], starts[i]) > 1e-2
    again = jc.localized_branches(RING, (2,), **kwargs)
    assert list(again["datasets"]) == labels


@pytest.mark.study
@pytest.mark.long
def test_branches_followed_by_two_workers_are_those_of_one(tmp_path):
    """`localized_branches(workers=2)`: the starts' branches, and those of the
    orbits deflation finds, followed in two processes side by side, are the
    branches of the sequential run to the last bit (each is the same compiled
    program), labelled and stored alike, and read back by a sequential call."""
    kwargs = dict(continuation_options=jc.ContinuationOptions(
        ds=0.02, ds_max=0.05, p_min=1.45, p_max=1.55, max_points=3),
        start_options=START, simulation_check=False, deflate=1)
    one = jc.localized_branches(RING, (2, 1), **kwargs, out=tmp_path / "one")
    two = jc.localized_branches(RING, (2, 1), **kwargs, out=tmp_path / "two", workers=2)
    assert list(two["datasets"]) == list(one["datasets"]) == [
        "k=2", "k=2 deflated 1", "k=1", "k=1 deflated 1"]
    for label, ds in one["datasets"].items():
        xr.testing.assert_identical(two["datasets"][label], ds)
    assert two["summary"]["deflated_on_followed"] == one["summary"]["deflated_on_followed"]
    back = jc.localized_branches(RING, (2, 1), **kwargs, out=tmp_path / "two")
    assert list(back["datasets"]) == list(one["datasets"])
    with pytest.raises(ValueError, match="workers"):
        jc.localized_branches(RING, (2,), **kwargs, workers=0)
