"""Grids of belt speeds and initial conditions run through the engine: `ensemble`
in memory, `sweep` in batches written to a zarr store as they finish; results as
xarray Datasets and the files they are kept in, written atomically."""
