"""The geometry of the finite-cover fluid domain on a fixed mesh (SPEC §1; issue #5).

The structure's level set s (signed distance, > 0 in the fluid) is held at the mesh
vertices as a P1 field. Its zero set cuts cells; integrals run over the fluid part of each
cut cell only, by moment-fitted weights at the points of the standard rule
(``moments.fitted_weights``), stored in a dolfinx Quadrature space:

    ∫_{Ω_f} f dx  = Σ_K Σ_q ŵ_q |J_K| c_q f(x_q)        (``CutDomain.dx``: f · c_v · dx_q)
    ∫_Γ f dΓ      = Σ_K Σ_q ŵ_q |J_K| d_q f(x_q)        (``surface`` weights d_q)

both exact for polynomials of degree ≤ 2 over the piecewise-planar cut geometry. Only cut
cells need the weights: the cells are tagged (``cell_tags``: uncut fluid, cut, solid) and the
uncut ones are integrated with the plain rule of degree ``plain_degree`` and no weight fields,
solid cells with the plain rule times α. The tags change in place with the cut; forms compiled
as :class:`~fcm_fsi.fluid.tagged_form.TaggedForm` follow them.

Cells inside bodies and vertices with tiny fluid support: the solid part of every cell
carries the fluid equations scaled by α ≪ 1 (a fictitious domain, as in the finite cell
method: volume factor c_v + α(1 − c_v)). Every vertex then has support of relative size
≥ α, so the system stays regular whatever the cut fraction, and the rigid-body motion
that the penalty imposes on Γ is a solution of the fictitious equations inside.

What the fluid imposes on Γ (the wall terms, the cut-cell extension, the loads on the bodies)
is fluid-side: :class:`fcm_fsi.fluid.cut_walls.CutDomain` adds it to this geometry.
"""
from __future__ import annotations

from dataclasses import dataclass

import basix
import dolfinx.mesh
import numpy as np
import ufl
from dolfinx import fem
from mpi4py import MPI

from .. import jit
from .moments import MomentInverses, cut_cells, fitted_weights

#: quadrature degree of all fluid forms on a cut mesh: the smallest standard rule with at
#: least as many points as monomials of degree ≤ 2 (2D: 7 points ≥ 6; 3D: 14 points ≥ 10)
CUT_QUADRATURE_DEGREE = {2: 5, 3: 4}

#: cell classes of the cut (``CutDomain.cell_tags`` values): every vertex in the fluid, cut by Γ,
#: every vertex in a body
FLUID_CELL, CUT_CELL, SOLID_CELL = 0, 1, 2


def cell_classes(values: np.ndarray) -> np.ndarray:
    """FLUID_CELL, CUT_CELL or SOLID_CELL per row of vertex level-set values (fluid where ≥ 0)."""
    classes = np.full(len(values), CUT_CELL, np.int32)
    classes[values.min(axis=1) >= 0] = FLUID_CELL
    classes[values.max(axis=1) < 0] = SOLID_CELL
    return classes


class WeightedMeasure:
    """``f * WeightedMeasure(dx, c)`` is ``f * c * dx``: a measure with a weight field."""

    def __init__(self, dx: ufl.Measure, weight) -> None:
        self.dx, self.weight = dx, weight

    def __rmul__(self, integrand):
        return (integrand * self.weight) * self.dx


class FluidMeasure:
    """``f * FluidMeasure`` = ∫ f over the fluid with the fictitious α inside bodies: the plain
    rule on uncut fluid cells, α × the plain rule on solid cells, the fitted volume weights
    (c_v(1 − α) + α at the points) on cut cells."""

    def __init__(self, plain: ufl.Measure, fitted: ufl.Measure, weight, alpha: float) -> None:
        self.plain, self.fitted, self.weight, self.alpha = plain, fitted, weight, alpha

    def __rmul__(self, integrand):
        return (integrand * self.plain(FLUID_CELL) + (self.alpha * integrand) * self.plain(SOLID_CELL)
                + (integrand * self.weight) * self.fitted(CUT_CELL))


@dataclass
class CutStatistics:
    """Global counts of the current cut (rank-summed)."""

    cut_cells: int
    solid_cells: int
    fluid_volume: float        # exact measure of the fluid part (m³; m² in 2D)
    surface: float             # exact measure of the cut surface (m²; m in 2D)
    min_cut_fraction: float    # smallest fluid fraction of a cut cell


class CutGeometry:
    """Quadrature weights, cell tags and body ownership of the cut fluid domain.

    mesh: dolfinx mesh (P1 simplices); alpha: fictitious-domain factor of the solid part;
    plain_degree: quadrature degree on uncut cells (default the cut rule's degree).

    Forms over :attr:`dx`, :attr:`dGamma` and :attr:`dExt` depend on :attr:`cell_tags`;
    compile them as :class:`~fcm_fsi.fluid.tagged_form.TaggedForm` so they follow the cut.
    """

    def __init__(self, mesh, alpha: float = 1e-3, plain_degree: int | None = None) -> None:
        self.mesh, self.comm = mesh, mesh.comm
        self.alpha = float(alpha)
        tdim = mesh.topology.dim
        self.gdim = mesh.geometry.dim
        self.degree = CUT_QUADRATURE_DEGREE[tdim]
        cell = mesh.ufl_cell()
        ct = basix.CellType.triangle if tdim == 2 else basix.CellType.tetrahedron
        self.ref_points, self.ref_weights = basix.make_quadrature(ct, self.degree)
        qe = ufl.FiniteElement("Quadrature", cell, self.degree, quad_scheme="default")
        self.Vq = fem.FunctionSpace(mesh, qe)
        self.volume_weight = fem.Function(self.Vq, name="fluid_weight")
        self.surface_weight = fem.Function(self.Vq, name="surface_weight")
        self.extension_weight = fem.Function(self.Vq, name="extension_weight")
        imap = mesh.topology.index_map(tdim)
        self.n_owned = imap.size_local
        # every owned cell tagged; until the first update all count as cut (weights everywhere)
        self.cell_tags = dolfinx.mesh.meshtags(mesh, tdim, np.arange(self.n_owned, dtype=np.int32),
                                               np.full(self.n_owned, CUT_CELL, np.int32))
        self.plain_degree = self.degree if plain_degree is None else int(plain_degree)
        self.dx_q = ufl.Measure("dx", domain=mesh, metadata={"quadrature_degree": self.degree})
        fitted = ufl.Measure("dx", domain=mesh, subdomain_data=self.cell_tags,
                             metadata={"quadrature_degree": self.degree})
        plain = ufl.Measure("dx", domain=mesh, subdomain_data=self.cell_tags,
                            metadata={"quadrature_degree": self.plain_degree})
        self.dx = FluidMeasure(plain, fitted, self.volume_weight, self.alpha)
        self.dGamma = WeightedMeasure(fitted(CUT_CELL), self.surface_weight)
        self.dExt = WeightedMeasure(fitted(CUT_CELL), self.extension_weight)   # solid part of cut cells

        ncells = imap.size_local + imap.num_ghosts
        nv = tdim + 1
        self.geom_cells = mesh.geometry.dofmap.array.reshape(ncells, -1)[:, :nv]
        self.cell_coords = np.ascontiguousarray(mesh.geometry.x[self.geom_cells][:, :, : self.gdim])
        own = self.cell_coords[: self.n_owned]
        self.owned_cell_volume = np.abs(np.linalg.det(own[:, 1:] - own[:, :1])) / (2.0 if self.gdim == 2 else 6.0)
        self.q_dofs = self.Vq.dofmap.list.array.reshape(ncells, -1)
        self.S1 = fem.FunctionSpace(mesh, ("Lagrange", 1))
        self.level_set = fem.Function(self.S1, name="structure_level_set")
        self.level_dofs = self.node_map(self.S1)
        self.cell_owner = np.full(ncells, -2, np.int64)
        self.cell_second, self.cell_share = np.full(ncells, -2, np.int64), np.zeros(ncells)
        self.body_cells = np.zeros(ncells, bool)
        self.fluid_measure = np.zeros(ncells)
        self.surface_measure = np.zeros(ncells)
        self._moment_inverses = MomentInverses(ncells)   # of the cells cut so far (the mesh is fixed)

    @property
    def fluid_fraction(self):
        """c_v at the quadrature points (1 fluid, 0 solid) as a UFL expression: the volume
        weight without the fictitious α."""
        return (self.volume_weight - self.alpha) / (1 - self.alpha)

    # ----------------------------------------------------------------- update
    def node_map(self, V: fem.FunctionSpace) -> np.ndarray:
        """Block dof of the P1 space ``V`` at each mesh vertex (:attr:`nodes` order): a P1
        space numbers the vertices of every cell in the geometry's local order."""
        cells = V.dofmap.list.array.reshape(self.geom_cells.shape[0], -1)
        out = np.empty(self.mesh.geometry.x.shape[0], np.int64)
        out[self.geom_cells.ravel()] = cells.ravel()
        return out

    @property
    def nodes(self) -> np.ndarray:
        """Mesh vertex coordinates (n, 3) [m] where the level set is given (this rank, incl. ghosts)."""
        return self.mesh.geometry.x

    def update(self, level: np.ndarray, owner: np.ndarray,
               share: tuple[np.ndarray, np.ndarray] | None = None) -> CutStatistics:
        """New cut from the level set at :attr:`nodes` (> 0 fluid) and the owning body of each
        node (int, < 0 for none/static). ``share`` = (second body, its weight in [0, ½]) at each
        node: a cell's load then goes to the two bodies of its deepest vertex in those
        proportions (default: all to the owner). Local work only, except the statistics (one
        allreduce)."""
        values = np.ascontiguousarray(level[self.geom_cells])
        cv, cs, self.fluid_measure, self.surface_measure = fitted_weights(
            self.cell_coords, values, self.ref_points, self.ref_weights, self._moment_inverses)
        a = self.alpha
        self.volume_weight.x.array[self.q_dofs] = (1 - a) * cv + a
        self.surface_weight.x.array[self.q_dofs] = cs
        classes = cell_classes(values)
        self.extension_weight.x.array[self.q_dofs] = np.where((classes == CUT_CELL)[:, None], 1.0 - cv, 0.0)
        self.cell_tags.values[:] = classes[: self.n_owned]
        self.level_set.x.array[self.level_dofs] = level
        # a cell belongs to the body owning its deepest vertex
        deepest = np.argmin(values, axis=1)
        rows = np.arange(len(values))
        self.cell_owner = owner[self.geom_cells[rows, deepest]]
        if share is None:
            self.cell_second, self.cell_share = np.full_like(self.cell_owner, -2), np.zeros(len(rows))
        else:
            self.cell_second = share[0][self.geom_cells[rows, deepest]]
            self.cell_share = np.where((self.cell_second >= 0) & (self.cell_owner >= 0),
                                       share[1][self.geom_cells[rows, deepest]], 0.0)
        self.body_cells = values[rows, deepest] <= 0     # cells at (cut or touching Γ) or inside a body
        return self.statistics(values)

    def fluid_fractions(self) -> np.ndarray:
        """Fluid fraction |K ∩ Ω_f| / |K| of every owned cell (0 solid … 1 fluid)."""
        return np.clip(self.fluid_measure[: self.n_owned] / self.owned_cell_volume, 0.0, 1.0)

    def statistics(self, values: np.ndarray) -> CutStatistics:
        own = slice(0, self.n_owned)
        v = values[own]
        cut = cut_cells(v)
        solid = v.max(axis=1) < 0
        frac = self.fluid_measure[own][cut] / self.owned_cell_volume[cut]
        s = self.comm.allreduce
        return CutStatistics(cut_cells=s(int(cut.sum())), solid_cells=s(int(solid.sum())),
                             fluid_volume=s(float(self.fluid_measure[own].sum())),
                             surface=s(float(self.surface_measure[own].sum())),
                             min_cut_fraction=self.comm.allreduce(float(frac.min(initial=1.0)), op=MPI.MIN))

    def wall_normal(self):
        """Unit normal of Γ pointing out of the fluid (into the body): −∇s/|∇s|, cell-wise."""
        g = ufl.grad(self.level_set)
        return -g / ufl.sqrt(ufl.inner(g, g) + 1e-300)

    def _to_bodies(self, cellwise: np.ndarray, nbodies: int) -> np.ndarray:
        """Sum owned-cell values (n_owned, k) per body (nbodies, k) by the cell ownership of
        :meth:`update` (owner, and the shared part to the second body); cells of no body or
        of static shapes count for none. Local."""
        own = self.n_owned
        owner, second, w = self.cell_owner[:own], self.cell_second[:own], self.cell_share[:own]
        mask = owner >= 0
        shared = mask & (w > 0)
        # the owners' parts, then the second bodies' shares: the order np.add.at would sum in, by bincount
        body = np.concatenate([owner[mask], second[shared]])
        factor = np.concatenate([1.0 - w[mask], w[shared]])
        k = int(np.prod(cellwise.shape[1:], dtype=np.int64))
        values = np.concatenate([cellwise[mask], cellwise[shared]]).reshape(len(body), k) * factor[:, None]
        out = np.column_stack([np.bincount(body, weights=values[:, j], minlength=nbodies)
                               for j in range(values.shape[1])])
        return out.reshape((nbodies,) + cellwise.shape[1:])

    def fluid_volume(self) -> float:
        """∫ 1 over the fluid part by the fitted weights (equals the exact cut measure)."""
        vol = fem.assemble_scalar(jit.form(self.fluid_fraction * self.dx_q))
        return float(self.comm.allreduce(vol, op=MPI.SUM))

    def surface_area(self) -> float:
        """∫_Γ 1 by the fitted surface weights (equals the exact cut-surface measure)."""
        val = fem.assemble_scalar(jit.form(self.surface_weight * self.dx_q))
        return float(self.comm.allreduce(val, op=MPI.SUM))
