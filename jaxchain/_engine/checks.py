"""Checks of the arguments of the public entry points: a bad argument raises at
once, naming itself and what it accepts, before anything is traced or run."""

import diffrax
import numpy as np

from .options import SimulationOptions
from .._physics.forces import DEFAULT_EPS
from .._physics.params import ChainParams
from .solver.registry import AUTO, SOLVERS, auto_solver
from .._errors import ValidationError


def as_solver(solver, name: str = "solver", params: ChainParams | None = None,
              eps=DEFAULT_EPS) -> diffrax.AbstractSolver:
    """A diffrax solver, given as an instance, by name (`SOLVERS`), or as "auto":
    chosen from `params` smoothed at `eps` by `auto_solver` (the stiffness-aware
    ROS34PW2 unless eps is large), or ROS34PW2 when no params are given.

    **Raises:**

    `ValidationError` for an unknown name; `TypeError` for anything else that is not a
    `diffrax.AbstractSolver`.
    """
    if isinstance(solver, str):
        if solver == AUTO:
            return auto_solver(params, eps) if params is not None else SOLVERS["ros34pw2"]()
        if solver not in SOLVERS:
            raise ValidationError(f"{name} must be one of {', '.join(sorted(SOLVERS))}, "
                                  f"'{AUTO}' or a diffrax solver, got {solver!r}")
        return SOLVERS[solver]()
    if not isinstance(solver, diffrax.AbstractSolver):
        raise TypeError(f"{name} must be a diffrax solver, '{AUTO}' or one of "
                        f"{', '.join(sorted(SOLVERS))}, got {type(solver).__name__}")
    return solver


def check_params(params) -> ChainParams:
    """**Raises:** `TypeError` unless `params` is a `ChainParams`."""
    if not isinstance(params, ChainParams):
        raise TypeError(f"params must be a jaxchain.ChainParams, got {type(params).__name__}")
    return params


def check_options(options, cls=SimulationOptions, name: str = "options"):
    """**Raises:** `TypeError` unless `options` is an instance of `cls`."""
    if not isinstance(options, cls):
        raise TypeError(f"{name} must be a jaxchain.{cls.__name__}, got "
                        f"{type(options).__name__}")
    return options


def real_array(value, name: str) -> np.ndarray:
    """`value` as a float64 NumPy array.

    **Raises:**

    `TypeError` naming `name` when it is not real numbers (strings, booleans,
    complex numbers, objects).
    """
    try:
        a = np.asarray(value)
    except (TypeError, ValueError):  # ragged nested lists
        raise TypeError(f"{name} must be an array of real numbers, got {value!r}") from None
    if a.dtype == bool or not (np.issubdtype(a.dtype, np.integer)
                               or np.issubdtype(a.dtype, np.floating)):
        raise TypeError(f"{name} must be an array of real numbers, got dtype {a.dtype}")
    return a.astype(np.float64)


def belt_speeds(v_d, name: str = "v_d") -> np.ndarray:
    """Belt speeds as a non-empty 1-d float64 array.

    **Raises:**

    `TypeError` for non-numbers; `ValidationError` for an empty list, more than one
    dimension, or speeds that are not finite and > 0.
    """
    v = np.atleast_1d(real_array(v_d, name))
    if v.ndim != 1 or v.size == 0:
        raise ValidationError(f"{name} must be a 1-d list of at least one belt speed, "
                              f"got shape {v.shape}")
    if not np.all(np.isfinite(v) & (v > 0)):
        raise ValidationError(f"{name} must hold finite belt speeds > 0, got {v.tolist()}")
    return v


def check_run(params, solver, options, v_d) -> tuple:
    """The arguments that open every batched run (`ensemble`, `crosscheck`,
    `basin_stability`, `mistuning_study`), checked: (params, solver, options, v_d)
    as `check_params`, `as_solver`, `check_options` and `belt_speeds` return them.

    **Raises:**

    `ValidationError` (or `TypeError` for an argument of the wrong type) from those
    checks, naming the argument.
    """
    params = check_params(params)
    return params, as_solver(solver, params=params), check_options(options), belt_speeds(v_d)
