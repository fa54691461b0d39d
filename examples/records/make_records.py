"""Write the example records of `jaxchain identify`: a single oscillator on the belt
(eq. (5), n_osc = 1) with mu_st = 1.1, mu_d = 0.6, v0 = 0.35 (eq. (1)) and xi = 0.04,
started at rest, recorded by the event-driven non-smooth reference at three belt
speeds for 60 time units every 0.1, with Gaussian noise of 0.5 % of the amplitude.

    python examples/records/make_records.py [FOLDER]

writes rig_vd0.4.csv, rig_vd0.7.csv and rig_vd1.csv (default: this folder)."""

import sys
from pathlib import Path

import jaxchain as jc

#: The rig's true parameters, which `jaxchain identify` should find.
TRUE = {"mu_st": 1.1, "mu_d": 0.6, "v0": 0.35, "xi": 0.04}
SPEEDS = (0.4, 0.7, 1.0)


def main(folder: Path) -> None:
    jc.configure()
    law = jc.ExponentialDecay(mu_st=TRUE["mu_st"], mu_d=TRUE["mu_d"], v0=TRUE["v0"])
    rig = jc.ChainParams(n_osc=1, xi=TRUE["xi"], friction=law)
    for seed, v_d in enumerate(SPEEDS):
        record = jc.reference_record(rig, v_d, t_end=60.0, dt=0.1, noise=0.005, seed=seed)
        print(jc.write_record(record, folder / f"rig_vd{v_d:g}.csv"))


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).parent)
