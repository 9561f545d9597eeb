"""Fluid ⇄ DEM coupling and the finite-cover cut (section ``coupling``; SPEC §1, §3)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from .fields import param
from .loader import ConfigError


@dataclass(frozen=True, kw_only=True)
class CouplingConfig:
    """How the DEM blocks cut the fluid mesh and exchange loads with it (docs/coupling.md)."""

    penalty: float = param(1.0e4, doc="γ of the wall penalty p̄ = γ(μ/h + ρh/Δt). Large γ locks the cut cells' "
                                      "velocity to the wall and adds an entrained fluid layer ≈ 0.7 cells thick to "
                                      "every body's added mass (at R/h = 6.4: 1.66 ρV against 1.04; with wall_slip "
                                      "and γ = 10: 1.08), but γ = 10 with wall_slip diverged where a free surface meets a "
                                      "block (floating_box, bonded_wall_surge) and the coupled verification cases "
                                      "were measured with 1e4 (docs/design-notes.md)", gt=0, le=1e8)
    fictitious_factor: float = param(1.0e-3, doc="α: the solid part of each cell carries the fluid equations "
                                                 "scaled by α (keeps tiny cut cells regular)", gt=0, lt=1)
    wall: Literal["penalty", "pressure", "nitsche"] = param(
        "pressure", doc="wall terms on Γ: penalty (the paper's; leaks under pressure: slip ≈ p/p̄); pressure: "
                        "penalty + the pressure part of the wall traction (no leak, stable for any cut); nitsche: "
                        "full symmetric Nitsche (needs p̄ ≳ μ/(f h) in cut cells of fluid fraction f)")
    wall_slip: bool = param(
        False, doc="the wall penalty (and the cut-cell extension) act on the normal velocity only: a slip wall "
                   "without shear, for meshes far coarser than the boundary layer, where a no-slip wall's discrete "
                   "reaction is a spurious shear of order ρ h |u|/Δt (docs/design-notes.md); false = no-slip")
    wall_velocity: Literal["end", "mean"] = param(
        "end", doc="block velocity the fluid's wall condition gets for the next step: end = v, ω at the end of the "
                   "DEM sub-steps; mean = their mean over the sub-steps (the displacement / Δt_f), which does not "
                   "alias vibrations of bonded blocks far faster than the fluid step into the fluid (docs/design-notes.md)")
    load_split: Literal["owner", "shared"] = param(
        "owner", doc="which block a cut cell's load (and a node's wall velocity) belongs to: owner = the block its "
                     "deepest vertex is deepest in; shared = where a second block's shape is within one cell (the "
                     "smallest, h) of as deep, the two share it, the second's weight ½ − (d₂ − d₁)/(2h) ≥ 0 — continuous where "
                     "widened shapes overlap and blocks turn, where owner jumps between bonded neighbours every "
                     "step (docs/design-notes.md)")
    wall_motion: Literal["block", "bonded_cluster"] = param(
        "block", doc="whose rigid motion the fluid's wall velocity ū follows: block = each block's own v, ω; "
                     "bonded_cluster = the rigid motion (momentum and angular momentum kept) of the cluster of blocks "
                     "still joined by intact bonds, so the bonds' vibration (µm, faster than the fluid step) is not "
                     "fed into the wall condition, where neighbours' differing ū made the penalty push them apart "
                     "(docs/design-notes.md); a block whose bonds have all broken follows its own motion; a "
                     "cluster holding a fixed block is at rest")
    cut_extension: float = param(
        1.0, doc="β of the cut-cell extension: the solid part of every cut cell carries a Brinkman term "
                 "β ρ/Δt (u − ū) (its reaction is part of the block load) and β × the PSPG term, so nodes with "
                 "tiny fluid support follow the wall and the pressure extends smoothly into the body; 0 = off "
                 "(then the full floating_box level diverges at the contact line, docs/design-notes.md)", ge=0, le=100)
    gap_fill: float | None = param(
        None, unit="m", doc="fluid gaps narrower than this between a block and a DEM plane/box wall or another block "
                            "count as solid: level set min(φ, (d₁ + d₂ − δ)/2) over the two nearest owners, the fill's "
                            "load going to the nearer block and its wall velocity a continuous mix of the nearest "
                            "three owners' (each surface keeps its own; a wall's is 0) (a sub-cell gap under a block "
                            "resting on the floor otherwise squeezes it to the floor, docs/coupling.md); default = "
                            "the smallest cell; 0 = off; "
                            "must be below the level-set band", ge=0)
    vent_pockets: bool = param(True, doc="where the gap fill seals fluid off from the rest (a block landing "
                                         "beside a stopper on the floor traps water that the real, narrowing gap "
                                         "would let out), remove the fill — between owners free to part, not the "
                                         "blocks of one bonded structure — around the pocket until it reaches the "
                                         "rest of the fluid again (fcm/pockets.py, docs/coupling.md)")
    drain_pockets: bool = param(False, doc="hold the pressure of such pockets (vented or not) at the ambient one: "
                                           "the mean of the surrounding fluid's, moved hydrostatically to each "
                                           "node, a Dirichlet condition at the pocket's nodes that no cut cell "
                                           "touches — their water leaves and enters as past the sides of a block of "
                                           "finite depth in 3D. For 2D runs of blocks narrower than the channel, "
                                           "where a vent's sub-cell slit otherwise sets the pocket's pressure "
                                           "(block_overturn: +650 Pa under the sliding block, docs/coupling.md). "
                                           "The pocket's water volume is then not conserved in the "
                                           "plane. With vent_pockets false the fill keeps hiding the underside "
                                           "near the contacts (the lying block at rest: 0.44 N of lift instead of 3.6 N)")
    hidden_pressure: Literal["none", "linear", "hydrostatic"] = param(
        "hydrostatic", doc="the static part of the water's load on a block, and the parts of its surface that the "
                           "cut fluid does not reach (inside the gap fill where it lies on the floor, a stopper or "
                           "another block, or outside the mesh). hydrostatic: the block gets the flow's part of the "
                           "load on the cut surface and the local static pressure (the pressure at the top of the "
                           "vertical plus the weight of the fluid below, fluid/column_pressure.py) on its true "
                           "surface, extended over the hidden parts from the wetted surface around them as through "
                           "a thin gap: Archimedes' buoyancy on the block's true shape for every floating, resting "
                           "or submerged block and bonded structure, the flow's dynamic pressure on the wetted "
                           "surface only (so a surge adds no added mass through the hidden parts). linear: the same "
                           "with the whole pressure (the dynamic part follows the block's acceleration, an added "
                           "mass the explicit coupling does not stabilise). none: the whole load on the cut surface, "
                           "whose P1 level set cuts corners and curved faces (a sphere of 4 cells across loses 14 % "
                           "of its volume, and of its buoyancy) and hides what the fill covers (a block resting in "
                           "still water is pushed down by the water above it). The hidden part's load goes to the "
                           "block only (its reaction is the floor's), so exchange_error leaves it out "
                           "(coupling/hidden_load.py, docs/coupling.md)")
    min_thickness: float = param(0.0, unit="m", doc="box blocks (and structure blocks) thinner than this are widened "
                                                  "to it in the fluid's level set only (the DEM keeps their true "
                                                  "size): a wall thinner than about one cell falls between the mesh "
                                                  "nodes and lets water through", ge=0)
    unresolved_cells: float = param(
        0.0, doc="a moving block thinner in the fluid (after min_thickness) than this many cell sizes (the "
                 "mean edge of the cell holding its centre), or whose centre leaves the fluid mesh, is taken "
                 "out of the fluid's cut from then on and loaded as a point particle: buoyancy and drag "
                 "(unresolved_drag) from the flow at its centre, no torque; the fluid does not feel it. A block "
                 "below one cell falls between the mesh nodes and its cut-surface load is spurious "
                 "(coupling/unresolved.py, docs/coupling.md); 0 = never", ge=0, le=10)
    unresolved_drag: float = param(
        1.05, doc="drag coefficient C_d of the unresolved blocks' load ½ ρ C_d A |u − v| (u − v), A the block's "
                  "area across the relative velocity (a box's projection; other blocks the sphere of their "
                  "volume); 1.05: a cube face-on (Hoerner, Fluid-Dynamic Drag)", gt=0, le=10)
    force_relaxation: float = param(
        1.0, doc="ω: the DEM gets ω × the new fluid load + (1 − ω) × the load it got last step (torque alike); < 1 "
                 "damps the step-to-step oscillation of the explicit coupling (contact chatter of a block on the "
                 "floor fed back through the fluid) at the price of a lag of about (1 − ω)/ω fluid steps; 1 = off",
        gt=0, le=1)
    iterations: int = param(
        1, doc="passes of the fluid ⇄ DEM fixed-point iteration per fluid step: 1 = explicit (staggered); > 1 "
               "retakes the step from the same start, the fluid's wall velocity being the blocks' motion from the "
               "last pass as `wall_velocity` and `wall_motion` define it (updated by `iteration_method`), until "
               "`iteration_tol` (implicit coupling: the added mass drops out of the stability condition; each pass "
               "costs one fluid step)", ge=1, le=50)
    iteration_tol: float = param(1.0e-3, doc="converged when max |Δv| (ω × radius of gyration for rotations) ≤ this × "
                                             "max(max |v|, iteration_velocity)", gt=0, lt=1)
    iteration_velocity: float = param(1.0e-2, unit="m/s", doc="velocity scale floor of iteration_tol (blocks at rest)",
                                      gt=0)
    iteration_relaxation: float = param(0.5, doc="relaxation factor of the first pass's update (Aitken: its first factor)",
                                        gt=0, le=1)
    iteration_method: Literal["aitken", "iqn_ils", "iqn_mvj"] = param(
        "aitken", doc="update of the guessed velocities between passes (coupling/fixed_point.py): aitken = relaxed by "
                      "Aitken's Δ² factor (one scalar); iqn_ils = interface quasi-Newton with least-squares inverse "
                      "Jacobian from this step's passes (Degroote et al. 2009): fewer passes when few blocks move; "
                      "iqn_mvj = the same Jacobian carried into the next steps (multi-vector, Bogaers et al. 2014): "
                      "the first update of a step is a quasi-Newton one too")
    iteration_reuse: int = param(
        20, doc="iqn_mvj: steps whose passes the carried inverse Jacobian holds before it starts again from the "
                "identity", ge=1, le=1000)
    force_mode: Literal["hold", "linear"] = param(
        "hold", doc="fluid load over the DEM sub-steps: hold = constant; linear = ramp from the previous exchange")
    added_mass: float = param(0.0, doc="C_a of the added-mass stabilisation: each block's DEM inertia is raised by "
                                       "m̃ = C_a ρ̄ V_block (ρ̄: mean fluid density on the block's wetted surface, each step; "
                                       "V_block as the fluid sees it, i.e. widened by min_thickness) and the load by m̃ a "
                                       "of the previous fluid step "
                                       "(exact when converged; needed when the block's added mass exceeds its own)",
                              ge=0, le=20)
    added_mass_model: Literal["volume", "potential", "tensor"] = param(
        "volume", doc="what added_mass scales: volume = C_a ρ̄ V_block per block (above); potential = the added mass "
                      "the fluid has at this step — the largest eigenvalue of the translational added-mass tensor of "
                      "each moving block, or bonded cluster with wall_motion bonded_cluster, from the pressure impulse "
                      "of inviscid flow on the current cut and density (coupling/added_mass.py), shared out over the "
                      "cluster's blocks by volume; so it grows as a piece nears the floor or a neighbour (squeeze "
                      "film, docs/coupling.md); added_mass is then a factor on it (1 = the estimate itself); "
                      "tensor = the same solves, but the translational tensor itself is the DEM's added inertia "
                      "(m I + M̃, each direction its own added mass; rotations as potential): the largest eigenvalue "
                      "over-corrects the directions where the fluid answers less, and the lagged excess returns a "
                      "landing as a bounce (docs/design-notes.md)")
    depth: float | None = param(None, unit="m", doc="2D fluid only: out-of-plane extent of the blocks; the "
                                                   "per-unit-depth fluid force is multiplied by it", gt=0)
    band: float | None = param(None, unit="m", doc="level-set band half-width (default 2 × the largest cell)", gt=0)
    check_every: int = param(100, unit="steps", doc="compare the replicated DEM state across MPI ranks every this "
                                                    "many fluid steps", ge=1)

    def __post_init__(self) -> None:
        if self.drain_pockets and self.gap_fill == 0:
            raise ConfigError("key 'coupling.drain_pockets' = true needs the gap fill that seals the pockets: "
                              "'coupling.gap_fill' > 0 or unset (one cell)")
        if self.wall_slip and self.wall == "nitsche":
            raise ConfigError("key 'coupling.wall_slip' = true needs 'coupling.wall' 'penalty' or 'pressure' "
                              "(the Nitsche terms are no-slip)")
