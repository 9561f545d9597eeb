"""Registry of verification cases and the Metric record they return.

A case is a function ``run(level, out_dir, comm) -> list[Metric]`` registered with
:func:`register`. It runs on every rank of ``comm``; rank 0 writes plots into
``out_dir``. Modules in ``fcm_fsi/verify/cases/`` are imported automatically.
"""
from __future__ import annotations

import importlib
import math
import pkgutil
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

Level = Literal["quick", "full"]

_RESUME = False
_RANKS_PER_RUN = 1


def set_resume(flag: bool) -> None:
    """``--resume``: runs that find a checkpoint of their own case in their output folder
    continue from it instead of starting over (a long full level stopped by a crash or a
    reboot loses at most one checkpoint interval)."""
    global _RESUME
    _RESUME = bool(flag)


def set_ranks_per_run(k: int) -> None:
    """``--ranks-per-run``: how many ranks each of a case's independent runs gets (cases
    that run several, e.g. ``block_overturn``'s three frictions; 1 = side by side)."""
    global _RANKS_PER_RUN
    _RANKS_PER_RUN = max(1, int(k))     # the CLI refuses k < 1 with a message


def ranks_per_run() -> int:
    """The ``--ranks-per-run`` setting (default 1)."""
    return _RANKS_PER_RUN


def resume_checkpoint(run_dir: Path) -> str | None:
    """The checkpoint to continue a run in ``run_dir`` from, or None (not resuming, or no
    checkpoint there). The time loop refuses a checkpoint of a different case."""
    ck = Path(run_dir) / "checkpoint.h5"
    return str(ck) if _RESUME and ck.exists() else None


@dataclass(frozen=True)
class Metric:
    """One measured number against its reference and pass criterion."""

    key: str
    value: float
    reference: float | None
    tolerance: float | None
    unit: str
    passed: bool
    criterion: str

    def as_json(self) -> dict:
        def clean(x):
            return None if x is None or (isinstance(x, float) and not math.isfinite(x)) else x
        return {"value": clean(self.value), "reference": clean(self.reference),
                "tolerance": clean(self.tolerance), "unit": self.unit, "pass": bool(self.passed),
                "criterion": self.criterion}


def _f(x: float) -> float:
    return float(x)


def rel_error_metric(key: str, value: float, reference: float, rel_tol: float, unit: str = "-") -> Metric:
    """Value within ``rel_tol`` (relative) of a reference."""
    err = abs(value - reference) / abs(reference)
    return Metric(key, _f(value), _f(reference), _f(rel_tol), unit, bool(err <= rel_tol),
                  f"|value - ref|/|ref| = {err:.3g} <= {rel_tol:g}")


def at_most(key: str, value: float, limit: float, unit: str = "-", reference: float | None = 0.0) -> Metric:
    """An error measure that must not exceed ``limit``."""
    return Metric(key, _f(value), reference, _f(limit), unit, bool(value <= limit), f"value <= {limit:g}")


def at_least(key: str, value: float, limit: float, unit: str = "-", reference: float | None = None) -> Metric:
    """A quantity (e.g. an observed order) that must reach ``limit``."""
    return Metric(key, _f(value), reference, _f(limit), unit, bool(value >= limit), f"value >= {limit:g}")


def in_interval(key: str, value: float, lo: float, hi: float, unit: str = "-", reference: float | None = None) -> Metric:
    """A quantity that must lie in [lo, hi]."""
    return Metric(key, _f(value), reference, None, unit, bool(lo <= value <= hi), f"{lo:g} <= value <= {hi:g}")


def error_order(key: str, coarse: float, fine: float, reference: float, h_ratio: float, min_order: float,
                unit: str = "-") -> Metric:
    """Convergence toward a reference between two meshes whose cell sizes differ by ``h_ratio`` > 1:
    the observed order p = ln(|e_coarse| / |e_fine|) / ln(h_ratio) of the errors e = value − reference
    must reach ``min_order`` (0: the fine mesh is closer to the reference at all; 1: at least first
    order, i.e. the reference lies between the fine value and its first-order Richardson
    extrapolation). For a coarse level whose error the target tolerance cannot yet bound."""
    e_c, e_f = abs(coarse - reference), abs(fine - reference)
    p = math.log(e_c / e_f) / math.log(h_ratio) if e_c > 0 and e_f > 0 else (math.inf if e_f == 0 else -math.inf)
    passed = p > 0 if min_order == 0 else p >= min_order
    rel = f"|error| {e_c / abs(reference):.3g} -> {e_f / abs(reference):.3g} (h / {h_ratio:g})"
    return Metric(key, _f(p), None, _f(min_order), unit, bool(passed),
                  f"{rel}: observed order {p:.3g} {'> 0' if min_order == 0 else f'>= {min_order:g}'}")


def report_only(key: str, value: float, unit: str = "-", reference: float | None = None, note: str = "reported") -> Metric:
    """A number reported with no pass band (always passes; say why in ``note``)."""
    return Metric(key, _f(value), reference, None, unit, True, note)


RunFn = Callable[[Level, Path, object], list[Metric]]


@dataclass(frozen=True)
class VerificationCase:
    name: str
    description: str
    issue: int
    run: RunFn
    default_ranks: int = 1


REGISTRY: dict[str, VerificationCase] = {}


def register(name: str, description: str, issue: int, default_ranks: int = 1) -> Callable[[RunFn], RunFn]:
    """Decorator adding a verification case to the registry."""
    def wrap(fn: RunFn) -> RunFn:
        if name in REGISTRY:
            raise RuntimeError(f"verification case {name!r} registered twice")
        REGISTRY[name] = VerificationCase(name, description, issue, fn, default_ranks)
        return fn
    return wrap


def load_all() -> dict[str, VerificationCase]:
    """Import every module of ``fcm_fsi.verify.cases`` so their cases register."""
    from . import cases
    for mod in pkgutil.iter_modules(cases.__path__):
        importlib.import_module(f"{cases.__name__}.{mod.name}")
    return REGISTRY
