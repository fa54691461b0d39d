"""Sweeps: a grid of parameter values x initial conditions, run in batches through
the engine, each batch written to a zarr store as it finishes (`sweep`)."""
