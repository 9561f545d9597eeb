"""Checks a case must pass before anything is built: what the schema cannot see because it
needs the geometry of several sections at once, or the machine.

Every check is a function in :data:`CHECKS` returning :class:`Finding` s; an ``error`` stops the
run (exit code 2, one line naming the key, the value and what is allowed), a ``warning`` is
logged and the run goes on. The list with each check's docstring is part of
docs/case-reference.md (generated). ``python -m fcm_fsi validate CASE`` runs them all.

Nothing here builds a mesh or a solver: the mesh is estimated from its settings, the blocks'
geometry comes from the DEM state (numpy only).
"""
from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Literal

import numpy as np

from .config.case import Case
from .config.loader import ConfigError

#: gmsh cells per h^d of the target size h: the tsunami tank (30 × 10 × 12 m) at h = 0.2 m has
#: 2,008,185 tetrahedra, 4.46 per h³, a 12 × 4 × 6 m box at 0.5 m 4.92 (more surface per volume);
#: triangles: 2.31 per h², as equilateral ones (4/√3)
GMSH_CELLS_PER_H = {2: 2.31, 3: 4.7}
#: cells per vertex of a simplex mesh (2D: 2; 3D: 5.2 measured on gmsh boxes)
CELLS_PER_VERTEX = {2: 2.0, 3: 5.2}
#: memory per cell of a run [bytes]: the growth of the maximum resident set size (/usr/bin/time -v)
#: between two mesh sizes of one case, 1 rank. 3D: impact_box_3d (coupled, two-phase, GMRES +
#: block-Jacobi/ILU) 364 MB at 11,328 and 713 MB at 85,109 tetrahedra, 4.8 kB per cell; with a
#: direct solve (pc_type lu/cholesky) the factors take ≈ 15 kB per tetrahedron (the tsunami's
#: coarse level, docs/performance.md). 2D: dam_break_block (coupled, MUMPS LU) 337 MB at 12,000
#: and 552 MB at 48,000 triangles, 6.0 kB per cell
BYTES_PER_CELL = {2: 6.0e3, 3: 4.8e3}
BYTES_PER_CELL_DIRECT_3D = 1.5e4
#: memory of a rank before the mesh (Python, dolfinx, PETSc, Numba; the same measurements: 0.3 GB)
BYTES_PER_RANK = 3.0e8
#: gmsh holds the whole serial mesh on rank 0 while it meshes (9.4 GB for 1.0 × 10⁷ tetrahedra)
GMSH_BYTES_PER_CELL = 1.0e3


@dataclass(frozen=True)
class Finding:
    """One result of a pre-run check: ``error`` stops the run, ``warning`` is logged."""

    level: Literal["error", "warning"]
    key: str
    message: str

    def text(self) -> str:
        return f"key '{self.key}': {self.message}" if self.key else self.message


@dataclass(frozen=True)
class MeshEstimate:
    """Size of a case's mesh from its settings, before it is built."""

    dim: int
    cells: float
    vertices: float
    h_min: float             # smallest target cell size [m]
    unknowns: float          # P1 velocity + pressure (+ φ with a phase field)
    bytes_per_cell: float    # memory of the run per cell [bytes]

    def bytes_per_rank(self, ranks: int) -> float:
        """Peak memory of one rank of ``ranks`` [bytes] (gmsh's serial mesh on rank 0 aside)."""
        return BYTES_PER_RANK + self.bytes_per_cell * self.cells / ranks

    def bytes_on_node(self, ranks_on_node: int, ranks: int, gmsh: bool) -> float:
        """Memory the ranks of the node that holds rank 0 need together [bytes]."""
        serial = GMSH_BYTES_PER_CELL * self.cells if gmsh else 0.0
        return ranks_on_node * self.bytes_per_rank(ranks) + serial


# ------------------------------------------------------------------ the mesh estimate
def estimate_mesh(case: Case, face_area: float | None = None) -> MeshEstimate | None:
    """Cells, vertices, smallest size and unknowns of ``case.mesh`` from its settings (None without
    a mesh or for ``gmsh_file``, whose size only the file knows). ``face_area``: total face area
    (3D) or perimeter (2D) of the blocks the ``structure_band`` grades from [m², m]."""
    cfg = case.mesh
    if cfg is None or cfg.kind == "gmsh_file":
        return None
    d = cfg.dim
    if cfg.kind in ("rectangle", "box"):
        per_box = {"rectangle": 4 if cfg.diagonal == "crossed" else 2, "box": 6}[cfg.kind]
        cells = float(per_box) * math.prod(float(n) for n in cfg.cells)
        h_min = min((u - lo) / n for lo, u, n in zip(cfg.lower, cfg.upper, cfg.cells))
        vertices = math.prod(float(n) + 1 for n in cfg.cells) + (cells / 4 if cfg.diagonal == "crossed" and d == 2 else 0)
    else:
        cells, h_min = _gmsh_cells(cfg, face_area)
        vertices = cells / CELLS_PER_VERTEX[d]
    unknowns = vertices * ((d + 1) if case.fluid is not None else 0) + (vertices if case.phase_field is not None else 0)
    direct = case.fluid is not None and any(str(case.fluid.petsc.get(k, "")).lower() in ("lu", "cholesky")
                                            for k in ("pc_type", "sub_pc_type"))
    per_cell = BYTES_PER_CELL_DIRECT_3D if d == 3 and direct and case.fluid.petsc.get("pc_type") != "bjacobi" \
        else BYTES_PER_CELL[d]
    return MeshEstimate(d, cells, vertices, h_min, unknowns, per_cell)


def _gmsh_cells(cfg, face_area: float | None) -> tuple[float, float]:
    """∫ c_d / h(x)^d dx over the domain for the target size h(x) = min(size, refine zones), plus
    the structure band's layer ∫ (s + g δ)^−d on both sides of the faces (analytic)."""
    d, k = cfg.dim, GMSH_CELLS_PER_H[cfg.dim]
    lo, hi = np.array(cfg.lower, float), np.array(cfg.upper, float)
    if cfg.kind == "gmsh_disk":
        lo = 0.5 * (lo + hi) - cfg.radius
        hi = lo + 2 * cfg.radius
    n = 48 if d == 3 else 256
    axes = [lo[i] + (np.arange(n) + 0.5) * (hi[i] - lo[i]) / n for i in range(d)]
    pts = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, d)
    h = np.full(len(pts), cfg.size)
    h_min = cfg.size
    zones = [z for z in cfg.refine if len(z.lower) == d and len(z.upper) == d]   # others: check_points
    for z in zones:
        zl, zu = np.array(z.lower, float), np.array(z.upper, float)
        outside = np.linalg.norm(np.maximum(np.maximum(zl - pts, pts - zu), 0.0), axis=1)
        hz = np.where(outside == 0.0, z.size, z.size + z.grading * outside if z.grading is not None else np.inf)
        h = np.minimum(h, hz)
        h_min = min(h_min, z.size)
    volume = float(np.prod(hi - lo)) * (math.pi / 4 if cfg.kind == "gmsh_disk" else 1.0)
    cells = k * float(np.mean(h ** -d)) * volume
    # a zone thinner than the sampling grid is missed by it: its own cells are a lower bound
    cells = max(cells, k * sum(_zone_volume(z, lo, hi, d) / z.size ** d for z in zones))
    band = cfg.structure_band
    if band is not None and face_area:
        s, g, big = band.size, band.grading, cfg.size
        if d == 3:
            layer = face_area / g * (1.0 / s ** 2 - 1.0 / big ** 2)
        else:
            layer = 2.0 * face_area / g * (1.0 / s - 1.0 / big)
        cells += k * layer
        h_min = min(h_min, s)
    return cells, h_min


def _zone_volume(z, lo, hi, d) -> float:
    a = np.maximum(np.array(z.lower[:d], float), lo)
    b = np.minimum(np.array(z.upper[:d], float), hi)
    return float(np.prod(np.maximum(b - a, 0.0)))


def available_memory() -> float | None:
    """MemAvailable of this machine [bytes] (None where /proc/meminfo is not readable)."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return float(line.split()[1]) * 1024.0
    except OSError:
        return None
    return None


# ------------------------------------------------------------------ block geometry
def block_boxes(case: Case, state, structure) -> tuple[np.ndarray, np.ndarray, np.ndarray, float] | None:
    """World bounding boxes (lo, hi: (nb, 3)) of the blocks as the fluid sees them, a mask of the
    blocks it sees at all (a structure's foundation: no), and their total face area (3D) or
    perimeter (2D) for the structure band. None in a case without dem or mesh. ``state``, ``structure``:
    the case's DEM state and built structure (or None)."""
    if case.dem is None or case.mesh is None:
        return None
    from .coupling.dem_side import shapes_of_blocks
    from .fcm.levelset import MESH, SPHERE
    from .geometry import quat_to_matrix_np
    shapes = shapes_of_blocks(case.dem, state, case.coupling.min_thickness, structure)
    R = quat_to_matrix_np(state.quat)
    nb = state.nb
    lo, hi = np.full((nb, 3), np.inf), np.full((nb, 3), -np.inf)
    area = 0.0
    d = case.mesh.dim
    for kind, b, off, rot, half, tri in zip(shapes.kind, shapes.body, shapes.offset, shapes.rot, shapes.half,
                                            shapes.triangles):
        Rb = R[b]
        centre = state.pos[b] + Rb @ off
        if kind == MESH:                     # the surface's own extent, not its distance grid's
            corners = tri.reshape(-1, 3) @ (Rb @ rot).T
            lo[b] = np.minimum(lo[b], centre + corners.min(axis=0))
            hi[b] = np.maximum(hi[b], centre + corners.max(axis=0))
            area += 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1).sum()
            continue
        if kind == SPHERE:
            extent = np.full(3, half[0])
            area += 4 * math.pi * half[0] ** 2 if d == 3 else 2 * math.pi * half[0]
        else:
            extent = np.abs(Rb @ rot) @ half
            area += 8 * (half[0] * half[1] + half[1] * half[2] + half[2] * half[0]) if d == 3 else 4 * (half[0] + half[1])
        lo[b] = np.minimum(lo[b], centre - extent)
        hi[b] = np.maximum(hi[b], centre + extent)
    seen = np.isfinite(lo[:, 0])
    return lo, hi, seen, area


# ------------------------------------------------------------------ the checks
def check_memory(case: Case, ctx: Context) -> Iterator[Finding]:
    """Mesh size and memory: cells, vertices and unknowns are estimated from the mesh settings
    (structured: exact; gmsh: ∫ 4.7/h³ (3D) or 2.31/h² (2D) over the domain for the target size,
    plus the structure band's graded layer) and the memory per rank from measured runs: 0.3 GB
    per rank and 4.8 kB per tetrahedron (15 kB with a direct 3D solve) or 6.0 kB per triangle,
    1 kB per cell for gmsh's serial mesh on rank 0. An error when the ranks on this machine
    together need more than its available memory (MemAvailable), with the numbers and a hint to
    spread the run over more machines or coarsen the mesh."""
    est = ctx.estimate
    if est is None:
        return
    gmsh = case.mesh.kind in ("gmsh_box", "gmsh_disk")
    need = est.bytes_on_node(ctx.ranks_on_node, ctx.ranks, gmsh)
    if ctx.available is None or need <= ctx.available:
        return
    nodes = math.ceil(est.bytes_per_cell * est.cells / max(ctx.available - ctx.ranks_on_node * BYTES_PER_RANK, 1.0))
    m = case.mesh
    key, value = (("mesh.cells", list(m.cells)) if m.kind in ("rectangle", "box") else
                  ("mesh.structure_band.size", m.structure_band.size) if m.structure_band is not None else
                  ("mesh.size", m.size))
    serial = f", gmsh's serial mesh {GMSH_BYTES_PER_CELL * est.cells / 1e9:.3g} GB on rank 0" if gmsh else ""
    if gmsh and GMSH_BYTES_PER_CELL * est.cells > ctx.available:
        serial += (" — more than this machine has: generate it on a larger one (python -m fcm_fsi mesh CASE "
                   "--write FILE.msh) and run with mesh.kind gmsh_file")
    yield Finding("error", key, f"= {value}: ≈ {est.cells:.3g} cells, {est.unknowns:.3g} unknowns need ≈ "
                               f"{need / 1e9:.3g} GB on this machine ({est.bytes_per_rank(ctx.ranks) / 1e9:.3g} GB "
                               f"per rank × {ctx.ranks_on_node} rank(s) here{serial}), {ctx.available / 1e9:.3g} GB "
                               f"are available: spread the run over ≥ {nodes} machines of this size (mpirun -n N with "
                               f"a host file; more ranks on one machine do not help) or coarsen the mesh")


def check_liquid(case: Case, ctx: Context) -> Iterator[Finding]:
    """Initial liquid region: phase_field.initial must overlap the mesh (else there is no liquid:
    error) and, in a two-phase case, must not fill all of it (no free surface: warning)."""
    pf, m = case.phase_field, case.mesh
    if pf is None or m is None:
        return
    from .fluid.initial import signed_distance
    d = m.dim
    shape = pf.initial
    need = {"box": ("lower", "upper"), "circle": ("center",), "sphere": ("center",), "zalesak": ("center",)}
    for name in need.get(shape.shape, ()):
        value = getattr(shape, name)
        want = {"circle": (2, d), "zalesak": (2,)}.get(shape.shape, (d,))
        if len(value) not in want:
            yield Finding("error", f"phase_field.initial.{name}",
                          f"= {list(value)} needs {' or '.join(map(str, sorted(set(want))))} coordinates "
                          f"({shape.shape} in a {d}D mesh)")
            return
    n = 40 if d == 3 else 200
    axes = [lo + (np.arange(n + 1)) * (hi - lo) / n for lo, hi in zip(m.lower, m.upper)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=0).reshape(d, -1)
    x = np.vstack([grid, np.zeros((3 - d, grid.shape[1]))])
    sd = signed_distance(pf.initial, x, d)
    spacing = max((hi - lo) / n for lo, hi in zip(m.lower, m.upper))
    if not np.any(sd > -0.5 * spacing * math.sqrt(d)):
        yield Finding("error", "phase_field.initial",
                      f"the liquid region ({pf.initial.shape}) does not overlap the mesh "
                      f"{list(m.lower)}..{list(m.upper)}: there is no liquid to simulate")
    elif case.fluid is not None and np.all(sd > 0.5 * spacing * math.sqrt(d)):
        yield Finding("warning", "phase_field.initial",
                      f"the liquid region ({pf.initial.shape}) covers the whole mesh: no free surface")


def check_blocks(case: Case, ctx: Context) -> Iterator[Finding]:
    """Coupled cases: every block the fluid sees (a structure's foundation excepted) must overlap
    the fluid mesh (error: a block wholly outside never meets the fluid and the run would end
    without a word); a free block partly outside is a warning (the fluid acts on the part inside
    only, which may be meant: a block through the mesh's top), a fixed one is not reported (a
    fixed block sunk into the floor stands for a building's or a wall's foundation)."""
    if case.physics != "coupled" or ctx.blocks is None:
        return
    lo, hi, seen, _ = ctx.blocks
    d = case.mesh.dim
    mlo, mhi = np.array(case.mesh.lower, float), np.array(case.mesh.upper, float)
    tol = 1e-9 * max(1.0, float(np.max(np.abs(np.concatenate([mlo, mhi])))))
    partly = []
    fixed = ctx.state.fixed
    for b in np.flatnonzero(seen):
        blo, bhi = lo[b, :d], hi[b, :d]
        if np.any(bhi <= mlo + tol) or np.any(blo >= mhi - tol):
            yield Finding("error", _block_key(case, b),
                          f"block {b} spans {_fmt(blo)}..{_fmt(bhi)} m, wholly outside the fluid mesh "
                          f"{_fmt(mlo)}..{_fmt(mhi)} m (keys mesh.lower and mesh.upper): the fluid and the "
                          "block never meet")
        elif not fixed[b] and (np.any(blo < mlo - tol) or np.any(bhi > mhi + tol)):
            partly.append(b)
    if partly:
        b = partly[0]
        yield Finding("warning", _block_key(case, b),
                      f"{len(partly)} block(s) reach outside the fluid mesh {_fmt(mlo)}..{_fmt(mhi)} m (block {b}: "
                      f"{_fmt(lo[b, :d])}..{_fmt(hi[b, :d])} m); the fluid acts on the parts inside only")


def check_walls(case: Case, ctx: Context) -> Iterator[Finding]:
    """DEM blocks must not start inside a plane or box wall: a sphere of a free block overlapping a
    wall by more than 10 % of its radius starts with a contact force K × overlap that throws the
    block (error). Fixed blocks may (a foundation sunk into the ground); walls removed later
    (gates) are checked alike."""
    if case.dem is None or ctx.state is None:
        return
    st = ctx.state
    from .geometry import quat_to_matrix_np
    R = quat_to_matrix_np(st.quat)
    centres = st.pos[st.sph_block] + np.einsum("nij,nj->ni", R[st.sph_block], st.sph_local)
    r = st.sph_radius
    for i, w in enumerate(case.dem.walls):
        if w.kind == "plane":
            n = np.array(w.normal, float)
            n /= np.linalg.norm(n)
            gap = (centres - np.array(w.point)) @ n - r
        elif w.kind == "box":
            wlo, whi = np.array(w.lo), np.array(w.hi)
            gaps = np.concatenate([centres - wlo, whi - centres], axis=1)
            if w.open_top:
                gaps = gaps[:, :5]
            gap = gaps.min(axis=1) - r
        else:
            continue
        gap = np.where(st.fixed[st.sph_block], np.inf, gap)      # fixed blocks never move
        k = int(np.argmin(gap / r))
        if gap[k] < -0.1 * r[k]:
            b = int(st.sph_block[k])
            yield Finding("error", _block_key(case, b),
                          f"block {b} starts {-gap[k]:.3g} m deep in the {w.kind} wall dem.walls[{i}] (sphere radius "
                          f"{r[k]:.3g} m; allowed overlap ≤ 10 % of the radius): move the block or the wall")


def check_points(case: Case, ctx: Context) -> Iterator[Finding]:
    """Points and zones of the fluid inside its mesh: fluid.pressure_reference (where p = 0 is
    pinned) inside the mesh box; every mesh.refine zone and fluid.damping_zones layer overlapping
    the mesh (one wholly outside has no effect at all; error)."""
    m = case.mesh
    if m is None:
        return
    d = m.dim
    mlo, mhi = np.array(m.lower, float), np.array(m.upper, float)
    fl = case.fluid
    if fl is not None and fl.pressure_reference is not None:
        p = np.array(fl.pressure_reference[:d], float)
        if len(fl.pressure_reference) != d or np.any(p < mlo) or np.any(p > mhi):
            yield Finding("error", "fluid.pressure_reference",
                          f"= {list(fl.pressure_reference)} must be a point of the mesh {_fmt(mlo)}..{_fmt(mhi)} m "
                          f"({d} coordinates)")
    for i, z in enumerate(m.refine):
        if len(z.lower) != d or len(z.upper) != d:
            yield Finding("error", f"mesh.refine[{i}]", f"lower/upper need {d} coordinates, like mesh.lower")
        elif _zone_volume(z, mlo, mhi, d) <= 0.0:
            yield Finding("error", f"mesh.refine[{i}]",
                          f"zone {list(z.lower)}..{list(z.upper)} m does not overlap the mesh {_fmt(mlo)}..{_fmt(mhi)} m")
    for i, z in enumerate(fl.damping_zones if fl is not None else ()):
        a = "xyz".index(z.axis)
        if a < d and max(z.start, z.end) <= mlo[a] or a < d and min(z.start, z.end) >= mhi[a]:
            yield Finding("error", f"fluid.damping_zones[{i}]",
                          f"{z.axis} from {z.start:g} to {z.end:g} m lies outside the mesh's "
                          f"{mlo[a]:g}..{mhi[a]:g} m along {z.axis}")


def check_courant(case: Case, ctx: Context) -> Iterator[Finding]:
    """Courant number of the initial velocities U·Δt/h_min at the first step, in cases with a
    phase field or blocks (Δt = run.dt; the prescribed phase-field velocity, the velocity and
    inflow boundary values without a ramp, the blocks' initial velocities): above 10, the largest
    run.cfl the schema allows, an error; above 1 a warning (the interface or the cut moves more
    than a cell in a step). Navier–Stokes alone is implicit and may take any step (pseudo-time)."""
    if ctx.estimate is None or (case.phase_field is None and case.physics != "coupled"):
        return            # Navier–Stokes alone is implicit: a large step is a choice (pseudo-time)
    speeds: list[tuple[str, float]] = []
    pf = case.phase_field
    if pf is not None and pf.velocity is not None:
        v = pf.velocity
        if v.kind == "uniform":
            speeds.append(("phase_field.velocity.value", float(np.linalg.norm(v.value))))
        else:
            m = case.mesh
            far = max(np.linalg.norm(np.array(c)[:2] - np.array(v.center)[:2])
                      for c in _corners(m.lower, m.upper))
            speeds.append(("phase_field.velocity.omega", abs(v.omega) * far))
    if case.fluid is not None:
        for i, bc in enumerate(case.fluid.boundaries):
            if bc.ramp_time == 0.0 and bc.kind == "velocity":
                speeds.append((f"fluid.boundaries[{i}].value", float(np.linalg.norm(bc.value))))
            elif bc.ramp_time == 0.0 and bc.kind == "parabolic_inflow":
                speeds.append((f"fluid.boundaries[{i}].max_speed", bc.max_speed))
    if case.physics == "coupled":
        for i, b in enumerate(case.dem.blocks):
            speeds.append((f"dem.blocks[{i}].velocity", float(np.linalg.norm(b.velocity))))
    if not speeds:
        return
    key, u = max(speeds, key=lambda s: s[1])
    dt = case.run.dt
    courant = u * dt / ctx.estimate.h_min
    text = (f"speed {u:.4g} m/s gives the Courant number U·Δt/h = {courant:.3g} at the first step "
            f"(run.dt = {dt:g} s, smallest cell ≈ {ctx.estimate.h_min:.3g} m)")
    if courant > 10.0:
        yield Finding("error", key, text + "; allowed ≤ 10 (the largest run.cfl): lower run.dt")
    elif courant > 1.0:
        yield Finding("warning", key, text + ": more than a cell per step")


def check_dem_time_step(case: Case, ctx: Context) -> Iterator[Finding]:
    """DEM time step: dem.dt ≤ dem.dt_safety × Δt_cr, Δt_cr = 2√(m/k)(√(h²+1) − h) of the
    lightest effective contact mass and the stiffest contact (error; dem/model.py)."""
    if case.dem is None or ctx.state is None:
        return
    from .dem.model import build_system
    try:
        build_system(case.dem, with_ledger=False, structure=ctx.structure)     # refuses dt above the bound
    except ConfigError as err:
        yield Finding("error", "", str(err))


def check_pd_time_step(case: Case, ctx: Context) -> Iterator[Finding]:
    """Peridynamic time step: pd.dt ≤ Δt_crit = √(2ρ / Σ_j V_j c_ij/|ξ_ij|) of an interior
    lattice point (Silling–Askari bound; error; pd/builder.py)."""
    if case.pd is None:
        return
    from .pd.builder import check_time_step, lattice_stable_time_step
    try:
        check_time_step(case.pd.dt, lattice_stable_time_step(case.pd))
    except ConfigError as err:
        yield Finding("error", "", str(err))


CHECKS: tuple[Callable[[Case, Context], Iterator[Finding]], ...] = (
    check_memory, check_liquid, check_blocks, check_walls, check_points, check_courant, check_dem_time_step,
    check_pd_time_step)


# ------------------------------------------------------------------ running them
@dataclass
class Context:
    """What the checks share: the machine and rank count, the mesh estimate, the blocks."""

    ranks: int
    ranks_on_node: int
    available: float | None
    estimate: MeshEstimate | None
    blocks: tuple | None
    state: object | None
    structure: object | None


def check_case(case: Case, ranks: int = 1, ranks_on_node: int | None = None,
               available: float | None = -1.0) -> tuple[list[Finding], MeshEstimate | None]:
    """All pre-run findings of ``case`` on ``ranks`` ranks (``ranks_on_node`` of them on this
    machine; default all), and the mesh estimate. ``available``: memory [bytes] (default: this
    machine's MemAvailable; None: no memory check)."""
    state = blocks = structure = None
    if case.dem is not None:
        from .dem.model import build_state, build_structure
        structure = build_structure(case.dem)
        state = build_state(case.dem, structure)
        blocks = block_boxes(case, state, structure)
    face_area = blocks[3] if blocks is not None else None
    est = estimate_mesh(case, face_area)
    ctx = Context(ranks, ranks if ranks_on_node is None else ranks_on_node,
                  available_memory() if available == -1.0 else available, est, blocks, state, structure)
    findings = [f for check in CHECKS for f in check(case, ctx)]
    return findings, est


def run_checks(case: Case, comm, log) -> MeshEstimate | None:
    """Run :func:`check_case` on rank 0 for the ranks of ``comm`` (collective): warnings logged,
    the first error raised as ConfigError on every rank. Logs and returns the mesh estimate."""
    from mpi4py import MPI
    local = comm.Split_type(MPI.COMM_TYPE_SHARED)
    on_node = local.size
    local.Free()
    result = None
    if comm.rank == 0:
        try:
            findings, est = check_case(case, comm.size, on_node)
            result = ([(f.level, f.text()) for f in findings], est)
        except ConfigError as err:
            result = ([("error", str(err))], None)
    findings, est = comm.bcast(result, root=0)
    if est is not None:
        log.info("mesh estimate: ≈ %.3g cells, %.3g vertices, %.3g unknowns, ≈ %.2g GB per rank on %d rank(s)",
                 est.cells, est.vertices, est.unknowns, est.bytes_per_rank(comm.size) / 1e9, comm.size)
    for level, text in findings:
        if level == "warning":
            log.warning("%s", text)
    errors = [text for level, text in findings if level == "error"]
    if errors:
        raise ConfigError(errors[0])
    return est


def _corners(lower, upper) -> list[tuple[float, ...]]:
    import itertools
    return list(itertools.product(*zip(lower, upper)))


def _block_key(case: Case, b: int) -> str:
    """The key that places block ``b`` of the DEM state (blocks, generators, then the structure)."""
    from .dem.model import described_blocks
    for key, _, count in described_blocks(case.dem):
        if b < count:
            return f"{key}.position" if key.startswith("dem.blocks") else key.replace(".block", ".region_min")
        b -= count
    return "dem.structure.origin"


def _fmt(v) -> str:
    return "[" + ", ".join(f"{x:.4g}" for x in v) + "]"
