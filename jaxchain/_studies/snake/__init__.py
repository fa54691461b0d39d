"""The snake: branches of the chain's localized periodic states over the belt speed,
with their Floquet stability and bifurcations, started from direct simulation
(`run.localized_branches`)."""
