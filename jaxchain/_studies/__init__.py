"""Studies that compose the library: the cross-check against the non-smooth
reference, work-precision, the bistable range, the snake, the scenes of Figs. 5-10,
basin stability, the stress matrix and the mistuning studies."""
