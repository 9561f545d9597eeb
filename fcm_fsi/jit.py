"""How UFL forms and expressions are compiled: dolfinx's JIT with faster C flags.

Every form of the package is compiled by :func:`form` (and every interpolated expression by
:func:`expression`) instead of ``dolfinx.fem.form`` directly, so that all kernels get the same
C compiler flags:

    -O3 -march=native -fno-math-errno -fno-trapping-math -fno-signed-zeros -fassociative-math

instead of dolfinx's ``-O2``. The kernels are sums over quadrature points; with associative
math gcc vectorises those sums for the host's SIMD width. On the 2D dam break (a/20) the four
assemblies of a step (Navier–Stokes Jacobian and residual, phase-field matrix and vector) take
17 ms instead of 25 ms (docs/performance.md). What is *not* allowed: ``-ffinite-math-only``
(a NaN must still come out as NaN, so that a diverging run is detected) and reciprocal
approximations. Results change at round-off level against ``-O2``.

``-march=native`` builds for this host's instruction set. The JIT cache (~/.cache/fenics) is
keyed on the flags, and a home directory may be shared by machines with different CPUs, so the
flags also carry ``-DFCM_FSI_HOST_ISA=<hash>``, a hash of the instruction-set extensions gcc
enables here: another CPU gets its own modules instead of loading ones it cannot execute.
Where gcc cannot be asked, ``-march=native`` is left out.

A user's own ``cffi_extra_compile_args`` (``dolfinx_jit_parameters.json`` in the working
directory or ``~/.config/dolfinx/``) takes precedence over these flags.
"""
from __future__ import annotations

import functools
import hashlib
import os
import shlex
import subprocess
import sysconfig

from dolfinx import fem, jit

#: flags for every host: -O3 and the floating-point relaxations that let gcc vectorise sums
PORTABLE_FLAGS = ("-O3", "-fno-math-errno", "-fno-trapping-math", "-fno-signed-zeros", "-fassociative-math",
                  "-g0")


def c_compiler() -> list[str]:
    """The compiler command CFFI uses ($CC, else Python's build compiler)."""
    return shlex.split(os.environ.get("CC") or sysconfig.get_config_var("CC") or "gcc")


@functools.cache
def host_isa() -> str | None:
    """A short hash of the instruction-set options gcc's ``-march=native`` enables on this
    host (None when the compiler cannot be queried)."""
    try:
        out = subprocess.run([*c_compiler(), "-march=native", "-Q", "--help=target"], capture_output=True,
                             text=True, timeout=60, check=True).stdout
    except (OSError, subprocess.SubprocessError):
        return None
    enabled = sorted(" ".join(line.split()) for line in out.splitlines()
                     if line.strip().startswith("-m") and ("[enabled]" in line or "-march=" in line))
    if not enabled:
        return None
    return hashlib.sha1("\n".join(enabled).encode()).hexdigest()[:16]


@functools.cache
def compile_flags() -> tuple[str, ...]:
    """The C flags kernels are compiled with (module docstring)."""
    isa = host_isa()
    native = () if isa is None else ("-march=native", f"-DFCM_FSI_HOST_ISA={isa}")
    return PORTABLE_FLAGS + native


def jit_parameters() -> dict:
    """``jit_params`` for dolfinx: these flags, unless the user configured their own."""
    configured = jit.get_parameters().get("cffi_extra_compile_args")
    default = jit.DOLFINX_DEFAULT_JIT_PARAMETERS["cffi_extra_compile_args"][0]
    if configured is not None and list(configured) != list(default):
        return {}
    return {"cffi_extra_compile_args": list(compile_flags())}


def form(ufl_form, **kwargs) -> fem.FormMetaClass:
    """``dolfinx.fem.form`` with this package's compiler flags."""
    return fem.form(ufl_form, jit_params=jit_parameters(), **kwargs)


def expression(ufl_expression, points, **kwargs) -> fem.Expression:
    """``dolfinx.fem.Expression`` with this package's compiler flags."""
    return fem.Expression(ufl_expression, points, jit_params=jit_parameters(), **kwargs)
