"""The state of a peridynamic body and its velocity-Verlet step (eq 11), with the energy
account: kinetic, elastic (intact bonds), dissipated (the elastic energy the breaks released)
and the work of the boundary loads (prescribed velocities and tractions). The constitutive
model is a small object: :class:`BondBased` (eqs 3–4) or :class:`StateBased` (eqs 5–8)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .forces import break_bonds, damage, force_density
from .loads import PressureLoad
from .state import state_force_density, state_update


@dataclass
class Bonds:
    """Owned bonds as CSR (``offsets``, ``nbr``) with ``owner``, the dual lists (``dual_offsets``,
    ``dual_bond``) and per bond |ξ| ``length`` [m], ``beta`` [-], ``s0`` [-], ``intact`` (uint8)."""

    offsets: np.ndarray
    nbr: np.ndarray
    owner: np.ndarray
    dual_offsets: np.ndarray
    dual_bond: np.ndarray
    length: np.ndarray
    beta: np.ndarray
    s0: np.ndarray
    intact: np.ndarray

    @property
    def count(self) -> int:
        return len(self.nbr)


@dataclass
class Loads:
    """Boundary loads: ``fixed`` (N, 3) bool, the components with a prescribed velocity
    ``fixed_velocity`` (N, 3) [m/s]; ``body_force`` (N, 3) [N/m³] from the tractions (constant);
    ``pressures``, time-dependent pressures (boreholes, eq 12) as body forces."""

    fixed: np.ndarray
    fixed_velocity: np.ndarray
    body_force: np.ndarray
    pressures: tuple[PressureLoad, ...] = ()

    def body_force_at(self, t: float) -> np.ndarray:
        """The body force of all loads at time ``t`` [N/m³], (N, 3)."""
        if not self.pressures:
            return self.body_force
        out = self.body_force.copy()
        for p in self.pressures:
            p.add_body_force(t, out)
        return out


class BondBased:
    """Bond-based law (eq 3): micromodulus ``modulus`` C(δ_p) per point (eq 4)."""

    name = "bond_based"

    def __init__(self, modulus: np.ndarray):
        self.modulus = modulus

    def update(self, y: np.ndarray, b: Bonds, vol: np.ndarray, f: np.ndarray) -> tuple[float, float]:
        """Break the bonds past s0, then the force density at ``y`` into ``f``; returns (elastic
        energy, energy released by the breaks) [J]."""
        elastic, released = break_bonds(y, b.offsets, b.nbr, b.length, b.beta, b.s0, b.intact, self.modulus, vol)
        force_density(y, b.offsets, b.nbr, b.dual_offsets, b.dual_bond, b.owner, b.length, b.beta, b.intact,
                      self.modulus, vol, f)
        return float(elastic.sum()), float(released.sum())


class StateBased:
    """Ordinary state-based law (eqs 5–8, 3D): influence ``omega`` ω per bond (eq 8), weighted
    volume ``mvol`` m per point (eq 7), ``bulk`` K and ``shear`` G [Pa] per point; the dilatation
    ``theta`` θ per point of the last update."""

    name = "state_based"

    def __init__(self, omega: np.ndarray, mvol: np.ndarray, bulk: np.ndarray, shear: np.ndarray):
        self.omega, self.mvol, self.bulk, self.shear = omega, mvol, bulk, shear
        self.theta = np.zeros(len(mvol))

    def update(self, y: np.ndarray, b: Bonds, vol: np.ndarray, f: np.ndarray) -> tuple[float, float]:
        """As :meth:`BondBased.update`: breaks, θ, then the force density of eq 6."""
        elastic, released = state_update(y, b.offsets, b.nbr, b.length, b.beta, self.omega, b.s0, b.intact, vol,
                                         self.mvol, self.bulk, self.shear, self.theta)
        state_force_density(y, b.offsets, b.nbr, b.dual_offsets, b.dual_bond, b.owner, b.length, b.beta, self.omega,
                            b.intact, vol, self.mvol, self.theta, self.bulk, self.shear, f)
        return float(elastic.sum()), float(released.sum())


class PDSystem:
    """Points ``x`` (N, 3) [m] with volumes ``vol`` [m³], ``density`` ρ0 [kg/m³], the constitutive
    ``law`` (:class:`BondBased` or :class:`StateBased`), their ``bonds`` and ``loads``, stepped by
    ``dt`` [s]; ``horizon`` δ per point [m]."""

    def __init__(self, x, vol, density: float, law: BondBased | StateBased, bonds: Bonds, loads: Loads, dt: float,
                 velocity: np.ndarray | None = None, horizon: np.ndarray | None = None):
        self.x, self.vol, self.rho, self.law = x, vol, float(density), law
        self.bonds, self.loads, self.dt, self.horizon = bonds, loads, float(dt), horizon
        n = len(x)
        self.u = np.zeros((n, 3))
        self.v = np.zeros((n, 3)) if velocity is None else velocity.copy()
        self.v[loads.fixed] = loads.fixed_velocity[loads.fixed]
        self.f = np.zeros((n, 3))
        self.t, self.steps = 0.0, 0
        self.elastic = self.dissipated = self.work = 0.0
        self._update_bonds()
        self.power = self._power()
        self.initial_energy = self.kinetic() + self.elastic

    @property
    def modulus(self) -> np.ndarray:
        """C(δ_p) of a bond-based body (eq 4)."""
        return self.law.modulus

    # ------------------------------------------------------------ the step
    def _update_bonds(self) -> None:
        """Break the bonds past s0, then the force density at the current positions."""
        self.elastic, released = self.law.update(self.x + self.u, self.bonds, self.vol, self.f)
        self.dissipated += released

    def _kick(self) -> None:
        """Half a step of acceleration (ρ0 ü = f + b(t), eq 11) with the loads at the current time;
        prescribed components keep their velocity."""
        self.v += (0.5 * self.dt / self.rho) * (self.f + self.loads.body_force_at(self.t))
        fixed = self.loads.fixed
        self.v[fixed] = self.loads.fixed_velocity[fixed]

    def _power(self) -> float:
        """Power of the loads [W] at the current time: the tractions and pressures on the free
        components, and on the prescribed ones the force that holds their velocity against the
        bonds, −f V."""
        fixed, vol = self.loads.fixed, self.vol[:, None]
        load = np.where(fixed, -self.f * vol, self.loads.body_force_at(self.t) * vol)
        return float((load * self.v).sum())

    def step(self) -> None:
        """One velocity-Verlet step: kick with the loads at t, drift, bonds and forces, kick with
        the loads at t + dt; the loads' work by the trapezoidal rule of their power."""
        self._kick()
        self.u += self.dt * self.v
        self.t += self.dt
        self._update_bonds()
        self._kick()
        power = self._power()
        self.work += 0.5 * self.dt * (self.power + power)
        self.power = power
        self.steps += 1

    # ------------------------------------------------------------ what it reports
    def kinetic(self) -> float:
        """½ Σ ρ0 V |v|² [J]."""
        return 0.5 * self.rho * float((self.vol * (self.v ** 2).sum(axis=1)).sum())

    def damage(self) -> np.ndarray:
        """D of eq 9 per point."""
        b = self.bonds
        return damage(b.offsets, b.nbr, b.beta, b.intact, self.vol)

    def broken(self) -> int:
        return int(self.bonds.count - np.count_nonzero(self.bonds.intact))

    def energies(self) -> dict[str, float]:
        """kinetic, elastic, dissipated, external work [J] and the balance K + W + D − work − E(0),
        zero up to the integration error."""
        k = self.kinetic()
        balance = k + self.elastic + self.dissipated - self.work - self.initial_energy
        return {"kinetic_energy": k, "elastic_energy": self.elastic, "dissipated_energy": self.dissipated,
                "external_work": self.work, "energy_balance": balance}

    # ------------------------------------------------------------ checkpoint
    def arrays(self) -> dict[str, np.ndarray]:
        return {"pd__u": self.u, "pd__v": self.v, "pd__f": self.f, "pd__intact": self.bonds.intact,
                "pd__scalars": np.array([self.t, self.steps, self.elastic, self.dissipated, self.work,
                                         self.power, self.initial_energy])}

    def load_arrays(self, g: dict[str, np.ndarray]) -> None:
        self.u[...] = g["pd__u"]
        self.v[...] = g["pd__v"]
        self.f[...] = g["pd__f"]
        self.bonds.intact[...] = g["pd__intact"]
        t, steps, self.elastic, self.dissipated, self.work, self.power, self.initial_energy = (
            float(a) for a in g["pd__scalars"])
        self.t, self.steps = t, int(steps)
