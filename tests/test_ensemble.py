import jax.numpy as jnp
import numpy as np
import xarray as xr

import jaxchain as jc
from helpers import SHORT


def test_ensemble_equals_runs_done_one_at_a_time():
    """3 initial conditions x 2 belt speeds, vmapped in one compiled function, give
    the same observables as 6 separate `simulate` calls."""
    p = jc.ChainParams(n_osc=4)
    masks = np.stack([jc.excited_block(4, k) for k in (1, 2, 4)])
    ics = jc.OutOfPhaseExcitation(excited=jnp.asarray(masks), velocity=jnp.zeros(3))
    v_d = [1.3, 1.6]
    ds = jc.ensemble(p, v_d, ics, options=SHORT, progress=False)
    assert ds["amplitudes"].shape == (2, 3, 4) and ds["energy"].shape == (2, 3)
    assert ds["n_excited"].values.tolist() == [1, 2, 4]
    for i, vd in enumerate(v_d):
        for j, mask in enumerate(masks):
            single = jc.simulate(jc.ChainParams(n_osc=4, v_d=vd),
                                 jc.OutOfPhaseExcitation.eq8(mask), options=SHORT)
            lane = ds.isel(v_d=i, ic=j)
            for name in ("amplitudes", "energy", "n_halc", "min_slip_speed", "v_max",
                         "y_initial", "y_final", "num_steps", "status"):
                assert np.allclose(lane[name], getattr(single, name), rtol=1e-9,
                                   atol=1e-12), name


def test_a_failing_trajectory_is_flagged_and_the_others_kept():
    p = jc.ChainParams(n_osc=2)
    good = jc.OutOfPhaseExcitation.eq8([True, False])(p)
    y0 = jnp.stack([good, good.at[0, 0].set(jnp.nan)])
    ds = jc.ensemble(p, [1.5], jc.GivenState(y0), options=SHORT, progress=False)
    assert ds["status"].values.tolist() == [[0, 3]]  # non-finite initial state
    assert np.all(np.isnan(ds["amplitudes"][0, 1])) and int(ds["n_halc"][0, 1]) == -1
    assert int(ds["num_steps"][0, 1]) == 0  # skipped, holding up no other lane
    single = jc.simulate(p, good, options=SHORT)
    assert np.allclose(ds["amplitudes"][0, 0], single.amplitudes, rtol=1e-9)


def test_dataset_round_trip_keeps_parameters(tmp_path):
    p = jc.ChainParams(n_osc=3, eps=2e-2)
    ics = jc.localized_family(3)
    ds = jc.ensemble(p, [1.5], ics, options=SHORT, progress=False)
    path = jc.save_dataset(ds, tmp_path / "out" / "run.nc")
    back = xr.load_dataset(path)
    assert dict(back.sizes) == {"v_d": 1, "ic": 3, "osc": 3, "half": 2, "component": 2}
    assert back.attrs["eps"] == 2e-2 and back.attrs["n_osc"] == 3
    assert back.attrs["t_end"] == SHORT.t_end
    assert back.attrs["solver"] == type(jc.SOLVERS[jc.DEFAULT_SOLVER]()).__name__
    assert back["n_excited"].values.tolist() == [1, 2, 3]
    assert back.identical(ds)
    # eq. (8) at v_d = 1.5, stored: unexcited oscillators start at steady sliding
    ss = jc.steady_sliding(jc.ChainParams(n_osc=3, eps=2e-2))
    assert np.allclose(back["y_initial"].sel(component="x")[0, 0], np.asarray(ss[0]) + [0, 2, 0])
