"""The P1 strain G of the viscous reconstruction (``fluid.stabilization.viscous_reconstruction``).

On P1 elements ∇·(2μ ε(u)) vanishes inside each cell, so the strong residual of SUPG/PSPG
misses the viscous term. G, the lumped L2 projection onto P1 of ε(ũ) with the extrapolated
velocity ũ = (1 + θ)uⁿ − θuⁿ⁻¹ ≈ u^{n+θ} (O(Δt²)), restores it (``ns_forms``): it is fixed
during the step, so Newton keeps its quadratic convergence, and at a steady state ũ = u and
the strong residual is exactly consistent.
"""
from __future__ import annotations

import ufl
from dolfinx import fem
from petsc4py import PETSc

from .ns_forms import epsilon
from .tagged_form import TaggedForm


class StrainProjection:
    """Owns G (``field``, a P1 tensor function, 1/s) and its lumped-mass projection.

    mesh: the fluid mesh. dx: the volume measure of the Navier–Stokes forms (a cut measure:
    the projection then runs over the fluid part only, and the lumped mass, whose weights
    change with the cut, is re-assembled at every update); None for the whole mesh.
    theta: the θ-scheme constant. u_n, u_nm1: the velocities at tⁿ and tⁿ⁻¹ (UFL).
    """

    def __init__(self, mesh, dx: ufl.Measure | None, theta, u_n, u_nm1) -> None:
        gdim = mesh.geometry.dim
        T = fem.TensorFunctionSpace(mesh, ("Lagrange", 1))
        self.field = fem.Function(T, name="strain_p1")
        psi = ufl.TestFunction(T)
        dxp = dx if dx is not None else ufl.Measure("dx", domain=mesh, metadata={"quadrature_degree": 1})
        self._mass = TaggedForm(ufl.inner(ufl.as_matrix([[1.0] * gdim] * gdim), psi) * dxp)
        self._mass_fixed = dx is None
        self._lumped = fem.petsc.assemble_vector(self._mass.form)
        self._lumped.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        self._rhs_vec = self._lumped.duplicate()
        u_extrap = (1 + theta) * u_n - theta * u_nm1
        self._rhs = TaggedForm(ufl.inner(epsilon(u_extrap), psi) * dxp)

    def update(self) -> None:
        """G from the current uⁿ, uⁿ⁻¹ (and the current cut). Collective."""
        if not self._mass_fixed:
            with self._lumped.localForm() as loc:
                loc.set(0.0)
            fem.petsc.assemble_vector(self._lumped, self._mass.form)
            self._lumped.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        b = self._rhs_vec
        with b.localForm() as loc:
            loc.set(0.0)
        fem.petsc.assemble_vector(b, self._rhs.form)
        b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        b.pointwiseDivide(b, self._lumped)
        b.copy(self.field.vector)
        self.field.x.scatter_forward()
