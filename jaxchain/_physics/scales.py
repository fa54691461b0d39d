"""The scales of a dimensionless chain: the units of eqs. (4)-(6) of the paper in
SI, for a chain made from physical units (`jaxchain._physics.units`)."""

import equinox as eqx
import numpy as np


class Scales(eqx.Module):
    """The scales of the dimensionless chain, eqs. (4)-(6) of the paper, from its
    reference oscillator (mass m, ground stiffness k, normal load P):

    - `length`: x_0 = P / k, in m;
    - `time`: 1 / omega_n = sqrt(m / k), in s;
    - `velocity`: x_0 omega_n, in m/s;
    - `mass`, `stiffness`, `force`: m in kg, k in N/m, P in N.

    A displacement x in m is x_0 x~; a time t in s is t~ / omega_n; a dimensionless
    angular frequency omega~ is omega~ omega_n in rad/s, omega~ omega_n / (2 pi) in
    Hz.
    """

    length: float = eqx.field(static=True)
    time: float = eqx.field(static=True)
    velocity: float = eqx.field(static=True)
    mass: float = eqx.field(static=True)
    stiffness: float = eqx.field(static=True)
    force: float = eqx.field(static=True)

    @classmethod
    def of(cls, mass: float, stiffness: float, force: float) -> "Scales":
        """The scales of a reference oscillator of `mass` (kg), `stiffness` (N/m)
        and normal load `force` (N)."""
        length = force / stiffness
        time = float(np.sqrt(mass / stiffness))
        return cls(length=float(length), time=time, velocity=float(length / time),
                   mass=float(mass), stiffness=float(stiffness), force=float(force))

    def record(self) -> dict:
        """The scales as plain numbers, keys `scale_length`, ... (results' attributes
        and chain records)."""
        return {f"scale_{name}": getattr(self, name) for name in
                ("length", "time", "velocity", "mass", "stiffness", "force")}

    @classmethod
    def from_record(cls, record: dict) -> "Scales | None":
        """The scales of a record made by `record`, or None when it has none."""
        if "scale_length" not in record:
            return None
        return cls(**{name: float(record[f"scale_{name}"]) for name in
                      ("length", "time", "velocity", "mass", "stiffness", "force")})
