"""The package's form compilation (fcm_fsi/jit.py): faster flags, same numbers, NaN kept."""
from __future__ import annotations

import numpy as np
import pytest
import ufl
from dolfinx import fem
from dolfinx import jit as dolfinx_jit
from dolfinx import mesh as dmesh
from dolfinx.fem.petsc import assemble_matrix
from mpi4py import MPI

from fcm_fsi import jit
from fcm_fsi.fluid.phase_field import tau_phi


def supg_matrix_form(msh, u, dt):
    """A phase-field-like SUPG matrix: τ_φ (u·∇w)(u·∇φ) + w φ / Δt, with quadrature degree 3."""
    S = fem.FunctionSpace(msh, ("Lagrange", 1))
    phi, w = ufl.TrialFunction(S), ufl.TestFunction(S)
    dx = ufl.dx(metadata={"quadrature_degree": 3})
    h = ufl.CellDiameter(msh)
    return (tau_phi(u, dt, h) * ufl.dot(u, ufl.grad(w)) * ufl.dot(u, ufl.grad(phi)) + w * phi / dt) * dx


@pytest.fixture(scope="module")
def swirl():
    msh = dmesh.create_unit_square(MPI.COMM_WORLD, 12, 12)
    V = fem.VectorFunctionSpace(msh, ("Lagrange", 1))
    u = fem.Function(V)
    u.interpolate(lambda x: np.vstack([np.sin(np.pi * x[0]) * np.cos(np.pi * x[1]),
                                       -np.cos(np.pi * x[0]) * np.sin(np.pi * x[1])]))
    return msh, u, fem.Constant(msh, 1e-2)


def test_flags_relax_only_what_keeps_nan_and_exact_division():
    flags = jit.compile_flags()
    assert "-O3" in flags and "-fassociative-math" in flags
    for unsafe in ("-ffast-math", "-Ofast", "-ffinite-math-only", "-freciprocal-math"):
        assert unsafe not in flags
    if "-march=native" in flags:   # keyed by the host's instruction set in the JIT cache
        assert any(f.startswith("-DFCM_FSI_HOST_ISA=") for f in flags)


def test_a_users_own_compile_flags_take_precedence(monkeypatch):
    own = dict(dolfinx_jit.get_parameters(), cffi_extra_compile_args=["-O1"])
    monkeypatch.setattr(dolfinx_jit, "get_parameters", lambda *a, **k: own)
    assert jit.jit_parameters() == {}


def test_the_fast_kernels_assemble_the_default_kernels_matrix_to_round_off(swirl):
    msh, u, dt = swirl
    a = supg_matrix_form(msh, u, dt)
    fast = assemble_matrix(jit.form(a))
    fast.assemble()
    plain = assemble_matrix(fem.form(a, jit_params={"cffi_extra_compile_args": ["-O2", "-g0"]}))
    plain.assemble()
    plain.axpy(-1.0, fast)
    assert plain.norm() <= 1e-13 * fast.norm()


def test_tau_phi_is_eq_15(swirl):
    """1/√((2/Δt)² + 4 u·u/h²) equals [(2/Δt)² + (2|u|/h)²]^(-1/2) (eq 15) at every cell midpoint."""
    msh, u, dt = swirl
    h = ufl.CellDiameter(msh)
    eq15 = ((2.0 / dt) ** 2 + (2.0 * ufl.sqrt(ufl.dot(u, u)) / h) ** 2) ** -0.5
    dx = ufl.dx(metadata={"quadrature_degree": 3})
    diff = fem.assemble_scalar(jit.form((tau_phi(u, dt, h) - eq15) ** 2 * dx))
    ref = fem.assemble_scalar(jit.form(eq15 ** 2 * dx))
    assert diff <= 1e-26 * ref


def test_a_nan_coefficient_assembles_to_nan(swirl):
    """No finite-math-only: a NaN in the data must reach the result (the divergence check)."""
    msh, u, dt = swirl
    bad = fem.Function(u.function_space)
    bad.x.array[:] = u.x.array
    bad.x.array[5] = np.nan
    A = assemble_matrix(jit.form(supg_matrix_form(msh, bad, dt)))
    A.assemble()
    assert np.isnan(A.norm())
