"""Conservative Allen–Cahn phase field (section ``phase_field``; SPEC eqs 11, 14–17)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from .fields import param
from .petsc import check_petsc_options


@dataclass(frozen=True, kw_only=True)
class InitialShape:
    """Initial liquid region (φ = 1 inside), smoothed with the equilibrium profile of width ε."""

    shape: Literal["circle", "sphere", "zalesak", "box", "surface_wave"] = param(
        doc="circle (2D) / sphere (3D); zalesak: slotted disk; box: liquid block lower..upper; "
            "surface_wave: liquid below y = depth + amplitude·cos(π x / length)")
    center: tuple[float, ...] = param((0.0, 0.5), unit="m", doc="centre of circle/sphere/zalesak")
    radius: float = param(0.25, unit="m", doc="radius of circle/sphere/zalesak", gt=0)
    slot_width: float = param(0.05, unit="m", doc="zalesak slot width", gt=0)
    slot_depth: float = param(0.25, unit="m", doc="zalesak slot depth (from the bottom of the disk)", gt=0)
    lower: tuple[float, ...] = param((0.0, 0.0), unit="m", doc="box: lower corner of the liquid")
    upper: tuple[float, ...] = param((1.0, 1.0), unit="m", doc="box: upper corner of the liquid")
    bed_depth: float = param(0.0, unit="m", doc="box: also liquid below this height (a wet bed; 0 = none)", ge=0)
    depth: float = param(1.0, unit="m", doc="surface_wave: mean depth h", gt=0)
    amplitude: float = param(0.0, unit="m", doc="surface_wave: amplitude of cos(π x / length)")
    length: float = param(1.0, unit="m", doc="surface_wave: tank length L", gt=0)


@dataclass(frozen=True, kw_only=True)
class PrescribedVelocity:
    """A fixed advecting velocity for phase-field-only cases (no Navier–Stokes)."""

    kind: Literal["rotation", "uniform"] = param(doc="rotation: rigid rotation ω × (x − c) about z; uniform: constant vector")
    center: tuple[float, ...] = param((0.0, 0.0), unit="m", doc="rotation centre (x, y)")
    omega: float = param(1.0, unit="rad/s", doc="angular velocity of the rotation (counter-clockwise > 0)")
    value: tuple[float, ...] = param((0.0, 0.0), unit="m/s", doc="uniform velocity vector")


@dataclass(frozen=True, kw_only=True)
class PhaseFieldConfig:
    """φ = 1 liquid, 0 gas; φ_t + u·∇φ = γ ∇·(ε∇φ − φ(1−φ) ∇φ/|∇φ|) (conservative, Chiu & Lin 2011).

    In the paper's notation (eq 11) δ = ε (interface width) and the paper's mobility is γ·ε.
    """

    form: Literal["conservative", "nonconservative"] = param(
        "conservative", doc="conservative Allen–Cahn (eq 11) or the classical Allen–Cahn, for comparison")
    width_factor: float = param(0.6, doc="interface width ε = width_factor · h_min (h_min: smallest cell size)", gt=0, le=10)
    mobility_factor: float = param(1.0, doc="γ = mobility_factor · U, U = max |u| of the prescribed field (or "
                                            "reference_velocity)", ge=0, le=100)
    reference_velocity: float | None = param(None, unit="m/s", doc="velocity scale U for γ when the velocity is not "
                                                                   "prescribed", gt=0)
    mobility_length: float | None = param(
        None, unit="m", gt=0,
        doc="if set, γ = mobility_factor · U · min(1, h_min/mobility_length): the mobility falls in proportion to "
            "the mesh size below this length, so the sharpening's tangential smoothing (diffusivity γε) falls as h² "
            "and shape errors converge at first order; unset: γ independent of h (the paper)")
    width_floor: float | None = param(
        None, gt=0, le=10,
        doc="if set, the width in cell K is ε_K = max(ε, width_floor · h_K), h_K its longest edge: a mesh refined "
            "around the interface and coarse elsewhere gets in its coarse cells the width they can carry (where "
            "ε ≪ h the conservative sharpening flux amplifies φ's deviations from 0 and 1, docs/two-phase.md, sloshing); "
            "0.5 leaves every cell up to 2ε untouched; unset: ε in every cell")
    supg: bool = param(True, doc="SUPG stabilization with τ_φ of eq 15")
    picard_tolerance: float = param(1e-6, doc="Picard iterations stop when max |φ_k+1 − φ_k| falls below this", gt=0, lt=1)
    picard_max_iterations: int = param(10, doc="most Picard iterations per step; more is a divergence error. 1 = one "
                                               "solve linearised about the extrapolated φ* = 3/2 φⁿ − 1/2 φⁿ⁻¹ "
                                               "(second order, no iteration and no change test)", ge=1, le=100)
    volume_correction: bool = param(False, doc="shift the interface by L_err = V_err/A every step (eqs 16–17)")
    initial: InitialShape = param(doc="initial liquid region")
    velocity: PrescribedVelocity | None = param(None, doc="prescribed advecting velocity; omit when the fluid "
                                                          "section provides it")
    petsc: dict = param(default_factory=lambda: {"ksp_type": "gmres", "pc_type": "bjacobi", "sub_pc_type": "ilu",
                                                 "ksp_rtol": 1e-12, "ksp_atol": 1e-15},
                        doc="PETSc options of the φ solve (prefix pf_); the default GMRES + block-Jacobi/ILU "
                            "suits the mass-dominated system; tight tolerances keep ∫φ conserved")

    def __post_init__(self) -> None:
        check_petsc_options("phase_field.petsc", self.petsc)
