import jax.numpy as jnp
import numpy as np
import pytest
import xarray as xr

import jaxchain as jc
from helpers import TIGHT, assert_within_drift


@pytest.mark.numerics
@pytest.mark.study
def test_ensemble_equals_runs_done_one_at_a_time():
    """3 initial conditions x 2 belt speeds in one ensemble give the observables of
    6 separate `simulate` calls, in the order given. The ensemble's lanes and
    `simulate` are different compiled programs: the discrete observables agree
    exactly, the numbers within the integration tolerance (`drift_bound`, at
    `TIGHT`). The closest approach to the belt speed of an oscillator that sticks
    is of order eps, below what that tolerance resolves: it is compared for the
    oscillators that slip, and through on_halc for those that stick."""
    p = jc.ChainParams(n_osc=4)
    masks = np.stack([jc.excited_block(4, k) for k in (1, 2, 4)])
    ics = jc.OutOfPhaseExcitation(excited=jnp.asarray(masks), velocity=jnp.zeros(3))
    v_d = [1.3, 1.6]
    ds = jc.ensemble(p, v_d, ics, options=TIGHT, progress=False)
    assert ds["amplitudes"].shape == (2, 3, 4) and ds["energy"].shape == (2, 3)
    assert ds["n_excited"].values.tolist() == [1, 2, 4]
    for i, vd in enumerate(v_d):
        for j, mask in enumerate(masks):
            single = jc.simulate(jc.ChainParams(n_osc=4, v_d=vd),
                                 jc.OutOfPhaseExcitation.eq8(mask), options=TIGHT)
            lane = ds.isel(v_d=i, ic=j)
            for name in ("y_initial", "n_halc", "on_halc", "status"):
                assert np.array_equal(lane[name], getattr(single, name)), name
            assert int(lane["n_halc"]) >= 1  # it sticks
            steps = [int(lane["num_steps"]), int(single.num_steps)]
            for name in ("amplitudes", "v_max", "y_final"):
                assert_within_drift(lane[name], getattr(single, name), TIGHT, steps, name)
            slips = ~np.asarray(single.on_halc)
            if slips.any():
                assert_within_drift(lane["min_slip_speed"].values[slips],
                                    np.asarray(single.min_slip_speed)[slips], TIGHT, steps,
                                    "min_slip_speed")


#: For `test_good_lanes_are_kept_beside_failing_ones`: tolerances at which the
#: decaying lane's amplitudes (0.04) are compared to 0.12 % (`drift_bound`), and a
#: step budget per chunk of 30 that the sliding lanes keep within (about 12k steps)
#: and the stick-slipping lane exceeds (about 22k).
GOOD_AND_FAILING = jc.SimulationOptions(t_end=60.0, transient=30.0, chunk_length=30.0,
                                        rtol=1e-9, atol=1e-11, max_steps=16_000)


# the queue compares a lane with itself in one program (bitwise under any rounding);
# vmap compares two programs, and repeats every other check on the same lanes
@pytest.mark.study
@pytest.mark.parametrize("engine", ["queue", pytest.param("vmap", marks=pytest.mark.numerics)])
def test_good_lanes_are_kept_beside_failing_ones(engine):
    """One ensemble mixes good lanes (steady sliding, a decaying perturbation of it)
    with failing ones: a NaN initial state, and a stick-slipping lane whose step
    budget per chunk is too small. The failures are flagged, skipped and give no
    partial answers; every good lane equals its own separate run: bit for bit in
    the queue (the same compiled program), to rounding under vmap (a batch of 4
    lanes and one of 1 are different vectorised programs, which agree within the
    integration tolerance, `drift_bound`). Steady sliding stays where it is, a
    fixed point of eq. (5)."""
    p = jc.ChainParams(n_osc=2)
    sliding = jc.Exact().steady_sliding(p)
    lanes = jnp.stack([sliding.at[1, 0].add(0.1), sliding.at[0, 0].set(jnp.nan),
                       jc.OutOfPhaseExcitation.eq8([True, True])(p), sliding])
    options = GOOD_AND_FAILING
    ds = jc.ensemble(p, [1.5], jc.GivenState(lanes), options=options, schedule=engine,
                     progress=False).isel(v_d=0)
    s = jc.Status
    assert ds["status"].values.tolist() == [s.ok, s.non_finite_state, s.max_steps_reached, s.ok]
    for bad in (1, 2):
        assert np.all(np.isnan(ds["amplitudes"][bad])) and int(ds["n_halc"][bad]) == -1
        assert not ds["on_halc"][bad].any() and np.isnan(float(ds["energy"][bad]))
    assert int(ds["num_steps"][1]) == 0  # skipped, holding up no other lane
    for good in (0, 3):
        alone = jc.ensemble(p, [1.5], jc.GivenState(lanes[good:good + 1]), options=options,
                            schedule=engine, progress=False).isel(v_d=0, ic=0)
        assert int(ds["n_halc"][good]) == int(alone["n_halc"]) == 0
        steps = [int(ds["num_steps"][good]), int(alone["num_steps"])]
        for name in ("amplitudes", "energy", "y_final", "num_steps"):
            a, b = ds[name][good].values, alone[name].values
            if engine == "queue":
                assert np.array_equal(a, b), name
            elif name == "y_final" or (name == "amplitudes" and good == 0):
                # (energy follows from amplitudes; steady sliding's are zero, below)
                assert_within_drift(a, b, options, steps, name)
    assert float(ds["amplitudes"][0].min()) > 0.01  # the perturbation was observed
    assert np.all(ds["amplitudes"][3] < 1e-12)
    assert np.allclose(ds["y_final"][3], sliding, rtol=0, atol=1e-12)


def test_dataset_round_trip_keeps_parameters(tmp_path):
    p = jc.ChainParams(n_osc=3)
    ics = jc.localized_family(3)
    ds = jc.ensemble(p, [1.5], ics, engine=jc.Smoothed(options=TIGHT, eps=2e-2),
                     progress=False)
    path = jc.save_dataset(ds, tmp_path / "out" / "run.nc")
    back = xr.load_dataset(path)
    assert dict(back.sizes) == {"v_d": 1, "ic": 3, "osc": 3, "half": 2, "component": 2}
    assert back.attrs["eps"] == 2e-2 and back.attrs["n_osc"] == 3
    assert back.attrs["t_end"] == TIGHT.t_end
    assert back.attrs["solver"] == type(jc.SOLVERS["ros34pw2"]()).__name__
    assert back["n_excited"].values.tolist() == [1, 2, 3]
    xr.testing.assert_equal(back, ds)
    assert set(ds.attrs) <= set(back.attrs)  # every parameter, and the CF attributes
    assert back.attrs["Conventions"].startswith("CF-") and "jaxchain" in back.attrs["source"]
    assert back["energy"].attrs["units"] == "1" and "flag_values" in back["status"].attrs
    # eq. (8) at v_d = 1.5, stored: unexcited oscillators start at steady sliding
    ss = jc.Exact().steady_sliding(jc.ChainParams(n_osc=3))
    assert np.allclose(back["y_initial"].sel(component="x")[0, 0], np.asarray(ss[0]) + [0, 2, 0])
