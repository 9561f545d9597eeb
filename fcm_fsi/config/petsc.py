"""PETSc options from a case file (``fluid.petsc``, ``phase_field.petsc``), checked before any
solver is built: values of the right kind (numbers finite, tolerances positive, counts positive
integers, solver types that this PETSc has) and names that are not a near miss of a common
option. PETSc itself ignores an option it does not know, so a misspelt ``ksp_rtoll`` would
otherwise run silently with the default tolerance."""
from __future__ import annotations

import difflib
import functools
import math
import re

from .loader import ConfigError

#: option-name endings whose value is a positive real (tolerances, thresholds)
_POSITIVE_REAL = ("_rtol", "_atol", "_dtol", "_divtol", "_strong_threshold", "_threshold")
#: option-name endings whose value is an integer ≥ 1 (iteration counts, sizes)
_POSITIVE_INT = ("_max_it", "_restart", "_P_max", "_agg_nl", "_max_levels", "_agg_nsmooths", "_levels",
                 "_overlap", "_blocks")
#: option-name endings whose value is an integer ≥ 0
_NONNEGATIVE_INT = ("_factor_levels", "_agg_nsmooths", "_icntl_14", "_icntl_24")

#: options used by the project's solvers and cases, for the "did you mean" test of a name
_COMMON = (
    "ksp_type", "ksp_rtol", "ksp_atol", "ksp_dtol", "ksp_max_it", "ksp_gmres_restart", "ksp_norm_type",
    "ksp_initial_guess_nonzero", "ksp_monitor", "ksp_converged_reason", "ksp_view", "ksp_pc_side",
    "pc_type", "pc_factor_mat_solver_type", "pc_factor_levels", "pc_factor_shift_type",
    "pc_factor_mat_ordering_type", "pc_hypre_type", "pc_gamg_agg_nsmooths", "pc_gamg_threshold",
    "pc_fieldsplit_type", "pc_fieldsplit_schur_fact_type", "pc_fieldsplit_schur_precondition",
    "sub_ksp_type", "sub_pc_type", "sub_pc_factor_levels", "sub_pc_factor_shift_type",
    "sub_pc_factor_mat_ordering_type",
    "pc_hypre_boomeramg_strong_threshold", "pc_hypre_boomeramg_coarsen_type",
    "pc_hypre_boomeramg_interp_type", "pc_hypre_boomeramg_P_max", "pc_hypre_boomeramg_agg_nl",
    "pc_hypre_boomeramg_max_levels", "mat_mumps_icntl_14", "mat_mumps_icntl_24", "mat_mumps_cntl_1",
    "pc_bjacobi_blocks", "pc_asm_overlap")


@functools.lru_cache(maxsize=1)
def _types() -> dict[str, frozenset[str]]:
    """The KSP, PC and factor-package type names this PETSc build knows (lower case)."""
    from petsc4py import PETSc

    def names(enum) -> frozenset[str]:
        return frozenset(str(getattr(enum, k)).lower() for k in dir(enum) if not k.startswith("_"))
    return {"ksp_type": names(PETSc.KSP.Type), "pc_type": names(PETSc.PC.Type),
            "pc_factor_mat_solver_type": names(PETSc.Mat.SolverType)}


def _strip_split(name: str) -> str:
    """``fieldsplit_u_pc_type`` → ``pc_type``, ``sub_ksp_type`` → ``ksp_type`` (the option a
    block or sub-solver reads under its own prefix)."""
    if name.startswith("fieldsplit_"):
        rest = name[len("fieldsplit_"):]
        name = rest.split("_", 1)[1] if "_" in rest else rest
    while name.startswith("sub_"):
        name = name[len("sub_"):]
    return name


def check_petsc_options(key: str, options: dict) -> None:
    """Raise ConfigError naming ``key.option`` for a value PETSc would misread or a name that is
    a near miss of a common option. ``key``: the section's key path, e.g. ``fluid.petsc``."""
    for name, value in options.items():
        path = f"{key}.{name}"
        if not isinstance(name, str) or not name or name.startswith("-") or " " in name:
            raise ConfigError(f"key '{path}': option names are PETSc option names without the prefix "
                              f"and the leading '-', e.g. ksp_rtol")
        if isinstance(value, float) and not math.isfinite(value):
            raise ConfigError(f"key '{path}' = {value!r}: must be a finite number")
        if isinstance(value, str):
            try:
                as_number = float(value)
            except ValueError:
                as_number = None
            if as_number is not None and not math.isfinite(as_number):
                raise ConfigError(f"key '{path}' = {value!r}: must be a finite number")
        base = _strip_split(name)
        if base in _types():
            allowed = _types()[base]
            if not isinstance(value, str) or value.lower() not in allowed:
                close = difflib.get_close_matches(str(value).lower(), sorted(allowed), n=1)
                hint = f" (did you mean {close[0]!r}?)" if close else ""
                raise ConfigError(f"key '{path}' = {value!r} is not a {base.replace('_', ' ')} of this PETSc{hint}; "
                                  f"allowed: {', '.join(sorted(allowed))}")
            continue
        if name.endswith(_POSITIVE_REAL):
            number = _number(value)
            if number is None or not number > 0:
                raise ConfigError(f"key '{path}' = {value!r}: must be a number > 0")
            continue
        int_kind = ">= 0" if name.endswith(_NONNEGATIVE_INT) else ">= 1" if name.endswith(_POSITIVE_INT) else None
        if int_kind is not None:
            lowest = 0 if int_kind == ">= 0" else 1
            if isinstance(value, bool) or not isinstance(value, int) or value < lowest:
                raise ConfigError(f"key '{path}' = {value!r}: must be an integer {int_kind}")
            continue
        if name not in _COMMON:
            close = difflib.get_close_matches(name, _COMMON, n=1, cutoff=0.85)
            numbered = close and re.sub(r"\d+", "#", close[0]) == re.sub(r"\d+", "#", name)  # icntl_7 vs icntl_14
            if close and not numbered:
                raise ConfigError(f"key '{path}' is not a PETSc option this solver reads; did you mean "
                                  f"'{key}.{close[0]}'?")


def _number(value) -> float | None:
    if isinstance(value, bool):
        return None
    if isinstance(value, (int, float)):
        return float(value)
    try:
        return float(value)
    except (TypeError, ValueError):
        return None
