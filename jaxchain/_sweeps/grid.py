"""The grid of a sweep: the values of one parameter x families of initial
conditions, laid out as one flat list of trajectories and cut into batches."""

import dataclasses
from collections.abc import Mapping

import numpy as np

from .._physics.initial import (AbstractInitialCondition, OutOfPhaseExcitation, batch_length,
                        initial_states)
from .._engine.lanes import lane_params, take_lanes
from .._engine.programs import compiled
from .._physics.params import ChainParams, parameter_name, with_parameter
from .._engine.engines import Smoothed
from .._errors import ValidationError

#: The swept names that are settings of the engine, not fields of the chain.
ENGINE_PARAMETERS = ("eps",)


@dataclasses.dataclass(frozen=True)
class SweepGrid:
    """Values of one parameter x initial conditions. Trajectory t of the flat list
    runs value t // n_ics with initial condition t % n_ics; batch b holds the
    trajectories [b B, (b + 1) B) for a batch size B.

    **Arguments:**

    - `params`: the chain parameters; the field `name` is replaced by each value.
    - `name`: the swept field of `ChainParams` (see `parameter_name`), or "eps",
        the smoothed engine's smoothing velocity (`ENGINE_PARAMETERS`): then the
        chain is the same in every lane, and each lane runs the engine at its eps
        (`lane_engines`).
    - `values`: its values, shape (n_values,).
    - `families`: initial conditions by family name, each batched along the
        leading axis of its array fields (for example `localized_family(N)`).

    **Raises:**

    `ValidationError` for an empty or non-finite list of values, a value that
    `ChainParams` rejects (naming the field), no families, a family without a batch
    axis, or initial states of the wrong shape.
    """

    params: ChainParams
    name: str
    values: np.ndarray
    families: Mapping[str, AbstractInitialCondition]

    @classmethod
    def build(cls, params, where, values, ics) -> "SweepGrid":
        name = where if where in ENGINE_PARAMETERS else parameter_name(where, params)
        values = np.atleast_1d(np.asarray(values, dtype=float))
        if values.ndim != 1 or values.size == 0:
            raise ValidationError(f"{name}: the sweep needs a 1-d list of at least one value, "
                                  f"got shape {values.shape}")
        for value in values:  # validates every value, naming the field
            if name in ENGINE_PARAMETERS:
                Smoothed(eps=value)
            else:
                with_parameter(params, name, value)
        families = dict(ics) if isinstance(ics, Mapping) else {type(ics).__name__: ics}
        if not families:
            raise ValidationError("ics: the sweep needs at least one family of initial "
                                  "conditions")
        grid = cls(params, name, values, families)
        for family in families.values():  # shapes checked before anything runs
            batch_length(family)
            compiled(initial_states, grid._lane_params(np.array([0])),
                     take_lanes(family, np.array([0])))
        return grid

    def _lane_params(self, value: np.ndarray) -> ChainParams:
        """The chain of each lane, for the indices `value` into `values`."""
        if self.name in ENGINE_PARAMETERS:
            return lane_params(self.params, value.size)
        return lane_params(self.params, value.size, **{self.name: self.values[value]})

    def lane_values(self, start: int, stop: int) -> np.ndarray:
        """The swept value of each of the trajectories [start, stop)."""
        return self.values[np.arange(start, stop) // self.n_ics]

    @property
    def sizes(self) -> list[int]:
        return [batch_length(f) for f in self.families.values()]

    @property
    def n_ics(self) -> int:
        return sum(self.sizes)

    @property
    def n_trajectories(self) -> int:
        return self.values.size * self.n_ics

    def ic_coords(self) -> dict:
        """Coordinates along `ic`: `family` (the family's name) and `n_excited` (the
        number of excited oscillators of an eq. (8)/(10) excitation, -1 for other
        initial conditions)."""
        family, excited = [], []
        for name, ics in self.families.items():
            n = batch_length(ics)
            family += [name] * n
            if isinstance(ics, OutOfPhaseExcitation):
                mask = np.broadcast_to(np.asarray(ics.excited), (n, self.params.n_osc))
                excited += mask.sum(-1).tolist()
            else:
                excited += [-1] * n
        return {"family": ("ic", np.array(family, dtype=object)),
                "n_excited": ("ic", np.array(excited))}

    def lanes(self, start: int, stop: int) -> tuple[ChainParams, np.ndarray]:
        """The parameters (every field with a leading (lanes,) axis, `lane_params`) and the
        initial states, shape (lanes, 2, n_osc), of trajectories [start, stop)."""
        t = np.arange(start, stop)
        value, ic = t // self.n_ics, t % self.n_ics
        params = self._lane_params(value)
        y0 = np.empty((t.size, 2, self.params.n_osc))
        first = 0
        for family, n in zip(self.families.values(), self.sizes):
            here = (ic >= first) & (ic < first + n)
            if here.any():
                y0[here] = np.asarray(compiled(initial_states, take_lanes(params, here),
                                               take_lanes(family, ic[here] - first)))
            first += n
        return params, y0
