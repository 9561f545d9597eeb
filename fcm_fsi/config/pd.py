"""Peridynamic solids (section ``pd``; docs/peridynamics.md): bond-based or ordinary state-based PD
in the dual-horizon form, on a regular lattice or at the centroids of a gmsh tetrahedral mesh,
explicit velocity-Verlet time integration, bonds breaking at the critical stretch of the
fracture energy G0."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from .fields import param
from .loader import ConfigError

Formulation = Literal["plane_stress", "plane_strain", "3d"]
Model = Literal["bond_based", "state_based"]

#: the Poisson ratio a bond-based material has (seed §2 after eq 4): 1/3 in plane stress, 1/4 otherwise
BOND_BASED_POISSON = {"plane_stress": 1.0 / 3.0, "plane_strain": 0.25, "3d": 0.25}
#: the most lattice points a case may have (memory: ≈ 30–120 bonds of 40 bytes per point)
MAX_POINTS = 5.0e7


def _box_check(key: str, lower: tuple, upper: tuple, dim: int | None = None) -> None:
    if len(lower) != len(upper):
        raise ConfigError(f"key '{key}.lower' = {list(lower)} and 'upper' = {list(upper)} must have as many "
                          "coordinates")
    if dim is not None and len(lower) != dim:
        raise ConfigError(f"key '{key}.lower' = {list(lower)}: give {dim} coordinates for this {dim}D body")
    if any(a >= b for a, b in zip(lower, upper)):
        raise ConfigError(f"key '{key}.lower' = {list(lower)} must be below upper = {list(upper)} in every "
                          "coordinate")


@dataclass(frozen=True, kw_only=True)
class PDMaterialConfig:
    """Isotropic linear-elastic brittle material of a peridynamic body."""

    youngs_modulus: float = param(unit="Pa", doc="Young's modulus E (eq 4)", gt=0)
    poisson_ratio: float | None = param(None, doc="Poisson's ratio ν; bond-based PD fixes it (1/3 plane stress, "
                                                  "1/4 plane strain and 3D): if given it must be that value; "
                                                  "state-based PD needs it (any value in the range)",
                                        gt=0, lt=0.5)
    density: float = param(unit="kg/m^3", doc="mass density ρ0 (eq 11)", gt=0)
    fracture_energy: float | None = param(None, unit="J/m^2", doc="fracture energy G0 (mean over the bonds with a "
                                                                   "Weibull shape) that sets the critical stretch "
                                                                   "s0 (eq 10); null = bonds never break", gt=0)
    weibull_shape: float | None = param(None, doc="Weibull shape m of G0 per bond (mean = fracture_energy); null = "
                                                  "the same G0 for every bond", gt=0, le=100)
    weibull_seed: int = param(0, doc="random seed of the Weibull draw (reproducible per seed)", ge=0)

    def __post_init__(self) -> None:
        if self.weibull_shape is not None and self.fracture_energy is None:
            raise ConfigError("key 'pd.material.weibull_shape' needs pd.material.fracture_energy (its mean)")


@dataclass(frozen=True, kw_only=True)
class PDLatticeConfig:
    """A regular lattice of material points filling a box: a point at the centre of every cube
    (square in 2D) of edge Δx, each with the volume Δx³ (Δx² × thickness in 2D)."""

    lower: tuple[float, ...] = param(unit="m", doc="lower corner of the body, (x, y) or (x, y, z)")
    upper: tuple[float, ...] = param(unit="m", doc="upper corner of the body")
    spacing: float = param(unit="m", doc="lattice spacing Δx", gt=0)


@dataclass(frozen=True, kw_only=True)
class PDParticlesConfig:
    """Material points at the centroids of the tetrahedra of a gmsh mesh (seed §4), each with its
    tetrahedron's volume V; the local spacing h of a point is the cube root of the mean V of the
    points within horizon_factor × V^(1/3), and its horizon δ = horizon_factor × h. Either a .msh
    file or a box that gmsh meshes."""

    file: str | None = param(None, doc="gmsh .msh file with tetrahedra (relative to the case file); null: "
                                       "mesh the box lower … upper")
    lower: tuple[float, ...] | None = param(None, unit="m", doc="lower corner of the box gmsh meshes (x, y, z)")
    upper: tuple[float, ...] | None = param(None, unit="m", doc="upper corner of the box gmsh meshes")
    size: float | None = param(None, unit="m", doc="target tetrahedron edge length of the box mesh (the particle "
                                                   "spacing h ≈ V^(1/3) comes out ≈ 0.6 × size)", gt=0)

    def __post_init__(self) -> None:
        box = (self.lower, self.upper, self.size)
        if self.file is not None and any(v is not None for v in box):
            raise ConfigError("key 'pd.particles': give either 'file' or the box ('lower', 'upper', 'size'), "
                              "not both")
        if self.file is None and any(v is None for v in box):
            raise ConfigError("key 'pd.particles': give 'file' (a .msh) or all of 'lower', 'upper', 'size' "
                              "(a box gmsh meshes)")
        if self.file is None:
            _box_check("pd.particles", self.lower, self.upper, 3)
            extent = [b - a for a, b in zip(self.lower, self.upper)]
            cells = 5.0 * extent[0] * extent[1] * extent[2] / self.size ** 3    # gmsh: ≈ 5 tets per size³
            if self.size > min(extent):
                raise ConfigError(f"key 'pd.particles.size' = {self.size:g} m is larger than the box's smallest "
                                  f"extent {min(extent):g} m")
            if cells > MAX_POINTS:
                raise ConfigError(f"key 'pd.particles.size' = {self.size:g} m gives ≈ {cells:.3g} tetrahedra; "
                                  f"allowed ≤ {MAX_POINTS:.0e}")


@dataclass(frozen=True, kw_only=True)
class PDVelocityConfig:
    """Prescribed velocity of the points inside a box (e.g. the grips of a tension test)."""

    lower: tuple[float, ...] = param(unit="m", doc="lower corner of the region")
    upper: tuple[float, ...] = param(unit="m", doc="upper corner of the region")
    velocity: tuple[float | None, ...] = param(unit="m/s", doc="velocity per component; null leaves that "
                                                               "component free")


@dataclass(frozen=True, kw_only=True)
class PDTractionConfig:
    """A traction on a boundary: a body force t / h on the points of a layer of thickness h
    inside a box, so that the layer carries the force t per unit boundary area."""

    lower: tuple[float, ...] = param(unit="m", doc="lower corner of the boundary layer")
    upper: tuple[float, ...] = param(unit="m", doc="upper corner of the boundary layer")
    traction: tuple[float, ...] = param(unit="Pa", doc="traction vector t (force per boundary area)")
    layer_thickness: float | None = param(None, unit="m", doc="thickness h of the layer (default: one lattice "
                                                              "spacing Δx; particles: the mean local spacing "
                                                              "of the layer's points)", gt=0)


@dataclass(frozen=True, kw_only=True)
class PDInitialVelocityConfig:
    """An initial velocity of the points inside a box (default: the whole body)."""

    velocity: tuple[float, ...] = param(unit="m/s", doc="velocity (amplitude with profile half_cosine)")
    lower: tuple[float, ...] | None = param(None, unit="m", doc="lower corner of the region (null: the body)")
    upper: tuple[float, ...] | None = param(None, unit="m", doc="upper corner of the region (null: the body)")
    profile: Literal["uniform", "half_cosine"] = param("uniform", doc="uniform, or × cos(π (x_a − lower_a) / "
                                                                      "(upper_a − lower_a)) along axis a: the "
                                                                      "fundamental mode of a free-free bar")
    axis: int = param(0, doc="axis a of the half_cosine profile (0 = x)", ge=0, le=2)

    def __post_init__(self) -> None:
        if (self.lower is None) != (self.upper is None):
            raise ConfigError("keys 'pd.initial_velocity[].lower' and 'upper' are given together or not at all")


@dataclass(frozen=True, kw_only=True)
class PDNotchConfig:
    """A pre-notch that no bond may cross: a line segment (2D: two points) or a rectangle (3D:
    a corner and its two neighbouring corners)."""

    points: tuple[tuple[float, ...], ...] = param(unit="m", doc="2D: [start, end]; 3D: [corner, corner + edge 1, "
                                                                "corner + edge 2] (edges at a right angle)")


@dataclass(frozen=True, kw_only=True)
class PDBoreholeConfig:
    """A charged borehole in a 2D body (seed §3(2), eq 12): the lattice points inside the circle
    are removed from the body, no bond crosses it, and the blast pressure
    P(t) = P0 (e^{−αt} − e^{−βt}) / (e^{−αt0} − e^{−βt0}) pushes its wall radially outward
    (a body force on the points within one spacing Δx of the wall; docs/peridynamics.md §2)."""

    centre: tuple[float, ...] = param(unit="m", doc="centre of the hole (x, y)")
    radius: float = param(unit="m", doc="radius of the hole", gt=0)
    peak_pressure: float = param(unit="Pa", doc="peak pressure P0, reached at the rise time (eq 12)", gt=0,
                                 le=1.0e11)
    rise_time: float = param(unit="s", doc="rise time t0: the time of the peak, t0 = ln(β/α)/(β − α) (eq 12)",
                             gt=0, le=1.0)
    beta_over_alpha: float = param(doc="β/α of eq 12 (> 1): with t0 it sets the decay rates α and β", gt=1.0,
                                   le=1.0e3)


@dataclass(frozen=True, kw_only=True)
class PDConfig:
    """A peridynamic solid in the dual-horizon form (eqs 2–11 of the seed paper)."""

    model: Model = param("bond_based", doc="constitutive model: bond_based (eqs 3–4) or state_based (ordinary "
                                           "state-based, eqs 5–8; 3d only)")
    formulation: Formulation = param(doc="plane_stress, plane_strain (2D, lattice in x, y) or 3d (eq 4)")
    thickness: float = param(1.0, unit="m", doc="out-of-plane thickness of a 2D body (point volume Δx² × "
                                                "thickness)", gt=0)
    material: PDMaterialConfig = param(doc="elastic and fracture properties")
    lattice: PDLatticeConfig | None = param(None, doc="the body's material points on a regular lattice (or "
                                                      "particles)")
    particles: PDParticlesConfig | None = param(None, doc="the body's material points at the centroids of a "
                                                          "tetrahedral mesh (3d; or lattice)")
    horizon_factor: float = param(3.015, doc="horizon δ = horizon_factor × local spacing (Δx, or a "
                                             "particle's h ≈ V^(1/3); the seed uses 3.015–4.015)", ge=1.0, le=10.0)
    dt: float = param(unit="s", doc="time step of the velocity-Verlet integration (eq 11); refused above the "
                                    "stable step (Silling–Askari bound, the log states it)", gt=0)
    velocities: tuple[PDVelocityConfig, ...] = param((), doc="prescribed velocities on regions")
    tractions: tuple[PDTractionConfig, ...] = param((), doc="tractions on boundary layers")
    initial_velocity: tuple[PDInitialVelocityConfig, ...] = param((), doc="initial velocities (later entries "
                                                                          "override earlier ones)")
    notches: tuple[PDNotchConfig, ...] = param((), doc="pre-notches no bond crosses")
    boreholes: tuple[PDBoreholeConfig, ...] = param((), doc="2D: pressurised holes (blast pressure of eq 12 on "
                                                           "the wall; the points inside are removed)")

    @property
    def dim(self) -> int:
        return 3 if self.formulation == "3d" else 2

    @property
    def horizon(self) -> float:
        """δ [m] of a lattice body (particles have one per point)."""
        if self.lattice is None:
            raise ValueError("a particle body has a horizon per point (pd/particles.py)")
        return self.horizon_factor * self.lattice.spacing

    def __post_init__(self) -> None:
        if (self.lattice is None) == (self.particles is None):
            raise ConfigError("keys 'pd.lattice' and 'pd.particles': give exactly one (a regular lattice, or the "
                              f"centroids of a tetrahedral mesh); got {'both' if self.lattice else 'neither'}")
        if self.particles is not None and self.formulation != "3d":
            raise ConfigError(f"key 'pd.formulation' = {self.formulation!r}: pd.particles are the centroids of "
                              "tetrahedra; allowed: '3d'")
        if self.model == "state_based":
            self._check_state_based()
        else:
            self._check_bond_based_poisson()
        if self.lattice is not None:
            self._check_lattice()
        self._check_loads()

    def _check_state_based(self) -> None:
        if self.formulation != "3d":
            raise ConfigError(f"key 'pd.formulation' = {self.formulation!r}: model state_based is built in 3D "
                              "(eq 6); allowed: '3d'")
        if self.material.poisson_ratio is None:
            raise ConfigError("key 'pd.material.poisson_ratio' is required with pd.model = 'state_based' "
                              "(allowed 0 < ν < 0.5)")

    def _check_bond_based_poisson(self) -> None:
        nu = self.material.poisson_ratio
        fixed = BOND_BASED_POISSON[self.formulation]
        if nu is not None and abs(nu - fixed) > 1e-9:
            raise ConfigError(f"key 'pd.material.poisson_ratio' = {nu:g}: bond-based PD in {self.formulation} has "
                              f"ν = {fixed:.6g}; allowed: {fixed:.6g} or null (any ν with pd.model = "
                              "'state_based')")

    def _check_lattice(self) -> None:
        dim = self.dim
        lat = self.lattice
        _box_check("pd.lattice", lat.lower, lat.upper, dim)
        extent = [b - a for a, b in zip(lat.lower, lat.upper)]
        if lat.spacing > min(extent):
            raise ConfigError(f"key 'pd.lattice.spacing' = {lat.spacing:g} m is larger than the body's smallest "
                              f"extent {min(extent):g} m")
        points = 1.0
        for e in extent:
            points *= max(round(e / lat.spacing), 1)
        if points > MAX_POINTS:
            raise ConfigError(f"key 'pd.lattice.spacing' = {lat.spacing:g} m gives ≈ {points:.3g} points; allowed "
                              f"≤ {MAX_POINTS:.0e}")

    def _check_loads(self) -> None:
        dim = self.dim
        for i, v in enumerate(self.velocities):
            _box_check(f"pd.velocities[{i}]", v.lower, v.upper, dim)
            if len(v.velocity) != dim or all(c is None for c in v.velocity):
                raise ConfigError(f"key 'pd.velocities[{i}].velocity' = {list(v.velocity)}: give {dim} components, "
                                  "at least one a number")
        for i, t in enumerate(self.tractions):
            _box_check(f"pd.tractions[{i}]", t.lower, t.upper, dim)
            if len(t.traction) != dim:
                raise ConfigError(f"key 'pd.tractions[{i}].traction' = {list(t.traction)}: give {dim} components")
        for i, v in enumerate(self.initial_velocity):
            if v.lower is not None:
                _box_check(f"pd.initial_velocity[{i}]", v.lower, v.upper, dim)
            if len(v.velocity) != dim:
                raise ConfigError(f"key 'pd.initial_velocity[{i}].velocity' = {list(v.velocity)}: give {dim} "
                                  "components")
            if v.axis >= dim:
                raise ConfigError(f"key 'pd.initial_velocity[{i}].axis' = {v.axis}: allowed 0 … {dim - 1}")
        for i, n in enumerate(self.notches):
            want = 2 if dim == 2 else 3
            if len(n.points) != want or any(len(p) != dim for p in n.points):
                raise ConfigError(f"key 'pd.notches[{i}].points': give {want} points of {dim} coordinates "
                                  f"({'a segment' if dim == 2 else 'a corner and its two neighbours'})")
        for i, h in enumerate(self.boreholes):
            self._check_borehole(i, h)

    def _check_borehole(self, i: int, h: PDBoreholeConfig) -> None:
        """A hole of a 2D body, with its wall layer (one spacing) inside the lattice box."""
        key = f"pd.boreholes[{i}]"
        if self.dim != 2:
            raise ConfigError(f"key '{key}': boreholes are 2D (plane stress or strain); formulation is "
                              f"'{self.formulation}'")
        if len(h.centre) != 2:
            raise ConfigError(f"key '{key}.centre' = {list(h.centre)}: give 2 coordinates")
        lat = self.lattice
        reach = h.radius + lat.spacing
        for a, (c, lo, hi) in enumerate(zip(h.centre, lat.lower, lat.upper)):
            if c - reach < lo or c + reach > hi:
                raise ConfigError(f"key '{key}': the hole and its wall layer (radius {h.radius:g} m + Δx = "
                                  f"{reach:g} m around {list(h.centre)}) leave the body ('pd.lattice.lower' = "
                                  f"{list(lat.lower)}, 'pd.lattice.upper' = {list(lat.upper)}) along axis {a}; "
                                  f"allowed: centre in [{lo + reach:g}, {hi - reach:g}] m")
