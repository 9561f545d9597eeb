"""Structure builder: a compact building description → box blocks, surface spheres, bonds.

Every block is an axis-aligned solid box (:func:`fcm_fsi.dem.bodies.box_template`: mass and
principal inertia from the box and the density, body frame = box axes, so the orientation
starts at the identity). Spheres sit only on the block surface: their centres lie on the
surface of the box shrunk by one radius, so the spheres' envelope is the box and the spheres
of two touching blocks just touch. Every
pair of blocks sharing a face of positive area gets one cohesive bond on the shared
rectangle (:class:`fcm_fsi.dem.cohesive.BondFace`).

:func:`build_building` turns a :class:`~fcm_fsi.config.structure.StructureConfig` into box
lists; :func:`assemble` does the rest and serves any list of boxes (the verification cases
build beams and block pairs with it).
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from ..config.loader import ConfigError
from ..config.structure import CohesiveConfig, StructureConfig
from .bodies import box_template
from .cohesive import BondFace, CohesiveBonds, CohesiveLaw

KINDS = ("column", "wall", "slab", "block", "foundation")


@dataclass
class Structure:
    """Blocks (boxes) with surface spheres and the faces to bond; SI units, world frame."""

    lo: np.ndarray          # (nb, 3) box lower corners [m]
    hi: np.ndarray          # (nb, 3) box upper corners [m]
    kind: np.ndarray        # (nb,) index into KINDS
    storey: np.ndarray      # (nb,) storey index (-1 when not a building)
    mass: np.ndarray        # (nb,) [kg]
    inertia: np.ndarray     # (nb, 3) principal moments about the centre [kg m²]
    sph_block: np.ndarray   # (ns,)
    sph_local: np.ndarray   # (ns, 3) offset from the block centre, body frame [m]
    sph_radius: np.ndarray  # (ns,)
    sph_material: np.ndarray
    faces: list[BondFace]

    @property
    def nb(self) -> int:
        return self.lo.shape[0]

    @property
    def fixed(self) -> np.ndarray:
        """(nb,) bool: the blocks that never move (the foundation)."""
        return self.kind == KINDS.index("foundation")

    @property
    def pos(self) -> np.ndarray:
        return 0.5 * (self.lo + self.hi)

    @property
    def quat(self) -> np.ndarray:
        q = np.zeros((self.nb, 4))
        q[:, 0] = 1.0
        return q

    def subset(self, keep) -> Structure:
        """The blocks where ``keep`` is true, renumbered; faces to dropped blocks vanish."""
        keep = np.asarray(keep, bool)
        new_id = np.cumsum(keep) - 1
        sph = keep[self.sph_block]
        faces = [dataclasses.replace(f, a=int(new_id[f.a]), b=int(new_id[f.b]))
                 for f in self.faces if keep[f.a] and keep[f.b]]
        return Structure(lo=self.lo[keep], hi=self.hi[keep], kind=self.kind[keep],
                         storey=self.storey[keep], mass=self.mass[keep], inertia=self.inertia[keep],
                         sph_block=new_id[self.sph_block[sph]], sph_local=self.sph_local[sph],
                         sph_radius=self.sph_radius[sph], sph_material=self.sph_material[sph],
                         faces=faces)

    def to_state(self, fixed=None):
        """A :class:`fcm_fsi.dem.state.DEMState` at rest in the built configuration."""
        from .state import DEMState
        return DEMState.from_blocks(self.pos, self.quat, self.mass, self.inertia, self.sph_block,
                                    self.sph_local, self.sph_radius, self.sph_material,
                                    fixed=fixed)

    def bonds(self, law: CohesiveLaw, points_per_edge: int) -> CohesiveBonds:
        """Cohesive bonds on all shared faces, in the built (stress-free) configuration."""
        return CohesiveBonds.from_faces(law, self.faces, self.pos, self.quat, points_per_edge)


def touching_faces(lo: np.ndarray, hi: np.ndarray, tol: float = 1e-6) -> list[BondFace]:
    """Faces of positive area shared by pairs of non-overlapping axis-aligned boxes.

    For each axis the boxes are grouped by the coordinate of their upper face; a box whose
    lower face lies on the same plane and whose other two intervals overlap by more than
    ``tol`` touches. Cost O(N·k) with k boxes per plane."""
    faces = []
    e = np.eye(3)
    for k in range(3):
        u, v = (k + 1) % 3, (k + 2) % 3
        planes: dict[int, list[int]] = {}
        for i in range(lo.shape[0]):
            planes.setdefault(int(round(hi[i, k] / tol)), []).append(i)
        for j in range(lo.shape[0]):
            key = int(round(lo[j, k] / tol))  # neighbouring bins too: round-off near a bin edge
            for i in (i for kk in (key - 1, key, key + 1) for i in planes.get(kk, ())):
                if abs(hi[i, k] - lo[j, k]) > tol:
                    continue
                lo_uv = np.maximum(lo[i, [u, v]], lo[j, [u, v]])
                hi_uv = np.minimum(hi[i, [u, v]], hi[j, [u, v]])
                if np.all(hi_uv - lo_uv > tol):
                    c = np.empty(3)
                    c[k] = hi[i, k]
                    c[[u, v]] = 0.5 * (lo_uv + hi_uv)
                    faces.append(BondFace(a=i, b=j, centre=tuple(c), normal=tuple(e[k]),
                                          axis_u=tuple(e[u]), axis_v=tuple(e[v]),
                                          half_u=0.5 * (hi_uv[0] - lo_uv[0]),
                                          half_v=0.5 * (hi_uv[1] - lo_uv[1])))
    return faces


def assemble(lo, hi, *, density: float, sphere_radius: float, material: int = 0,
             kind=None, storey=None, spacing=None) -> Structure:
    """Blocks from boxes ``lo``/``hi`` (nb, 3): mass properties, surface spheres, faces.
    ``spacing`` (nb,) [m]: the largest surface-sphere centre spacing of each block (NaN or
    None: the default 2·``sphere_radius``)."""
    lo = np.asarray(lo, float).reshape(-1, 3)
    hi = np.asarray(hi, float).reshape(-1, 3)
    ext = hi - lo
    small = np.flatnonzero(ext.min(axis=1) < 2 * sphere_radius - 1e-12)
    if small.size:
        b = small[0]
        raise ConfigError(f"block {b} ({KINDS[kind[b]] if kind is not None else 'box'}) has an edge of "
                          f"{ext[b].min():g} m, thinner than two sphere radii "
                          f"(2·{sphere_radius:g} m); use larger members or smaller spheres")
    ext = np.where(np.abs(ext - 2 * sphere_radius) < 1e-9, 2 * sphere_radius, ext)  # round-off
    spacings = np.full(lo.shape[0], np.nan) if spacing is None else np.asarray(spacing, float)
    tmpl = [box_template(ext[b], density, sphere_radius, None if np.isnan(spacings[b]) else float(spacings[b]))
            for b in range(lo.shape[0])]
    nb = lo.shape[0]
    ns = [len(t.sph_radius) for t in tmpl]
    return Structure(
        lo=lo, hi=hi,
        kind=np.full(nb, KINDS.index("block")) if kind is None else np.asarray(kind, np.int64),
        storey=np.full(nb, -1) if storey is None else np.asarray(storey, np.int64),
        mass=np.array([t.mass for t in tmpl]), inertia=np.array([t.inertia for t in tmpl]),
        sph_block=np.repeat(np.arange(nb), ns).astype(np.int64),
        sph_local=np.concatenate([t.sph_local for t in tmpl]),
        sph_radius=np.concatenate([t.sph_radius for t in tmpl]),
        sph_material=np.full(sum(ns), material, dtype=np.int64),
        faces=touching_faces(lo, hi, tol=1e-6 * max(1.0, float(np.abs(hi).max()))))


def _cuts(a: float, b: float, extra, block_size: float) -> np.ndarray:
    """Cut lines of [a, b]: the ends and ``extra`` lines inside, then each interval cut
    into the fewest equal pieces no longer than ``block_size``."""
    lines = sorted({a, b, *[x for x in extra if a + 1e-9 < x < b - 1e-9]})
    out = [a]
    for x0, x1 in zip(lines[:-1], lines[1:]):
        n = max(1, math.ceil((x1 - x0) / block_size - 1e-9))
        out.extend(np.linspace(x0, x1, n + 1)[1:])
    return np.array(out)


def _grid_boxes(cx, cy, cz):
    """All cells of a tensor grid of cut lines → (lo, hi) arrays."""
    lo = np.stack(np.meshgrid(cx[:-1], cy[:-1], cz[:-1], indexing="ij"), -1).reshape(-1, 3)
    hi = np.stack(np.meshgrid(cx[1:], cy[1:], cz[1:], indexing="ij"), -1).reshape(-1, 3)
    return lo, hi


def building_boxes(cfg: StructureConfig):
    """Boxes of the building: (lo, hi, kind, storey) arrays; see :class:`StructureConfig`."""
    ox, oy, oz = cfg.origin
    gx = ox + np.concatenate([[0.0], np.cumsum(cfg.bays_x)])
    gy = oy + np.concatenate([[0.0], np.cumsum(cfg.bays_y)])
    cxs, cys = cfg.column
    t, bs = cfg.wall_thickness, cfg.block_size
    h_col = cfg.storey_height - cfg.slab_thickness
    los, his, kinds, storeys = [], [], [], []

    def add(lo, hi, kind, s):
        los.append(lo)
        his.append(hi)
        kinds.append(np.full(len(lo), KINDS.index(kind)))
        storeys.append(np.full(len(lo), s))

    for s in range(cfg.storeys):
        zb = oz + s * cfg.storey_height
        zc = _cuts(zb, zb + h_col, (), bs)
        for x in gx:
            for y in gy:
                add(*_grid_boxes(np.array([x - cxs / 2, x + cxs / 2]),
                                 np.array([y - cys / 2, y + cys / 2]), zc), "column", s)
        for side in cfg.walls:
            along_x = side in ("ymin", "ymax")
            grid = gx if along_x else gy
            half_col = cxs / 2 if along_x else cys / 2
            line = {"ymin": gy[0], "ymax": gy[-1], "xmin": gx[0], "xmax": gx[-1]}[side]
            for bay in range(len(grid) - 1):
                a, b = grid[bay] + half_col, grid[bay + 1] - half_col
                ops = [o for o in cfg.openings if o.storey == s and o.side == side and o.bay == bay]
                ca = _cuts(a, b, [a + o.offset for o in ops] + [a + o.offset + o.width for o in ops], bs)
                cz = _cuts(zb, zb + h_col, [zb + o.sill for o in ops] + [zb + o.sill + o.height for o in ops], bs)
                ct = np.array([line - t / 2, line + t / 2])
                lo, hi = _grid_boxes(ca, ct, cz) if along_x else _grid_boxes(ct, ca, cz)
                ax = 0 if along_x else 1
                keep = np.ones(len(lo), bool)
                for o in ops:
                    cen = 0.5 * (lo + hi)
                    inside = ((cen[:, ax] > a + o.offset) & (cen[:, ax] < a + o.offset + o.width)
                              & (cen[:, 2] > zb + o.sill) & (cen[:, 2] < zb + o.sill + o.height))
                    keep &= ~inside
                add(lo[keep], hi[keep], "wall", s)
        zs = zb + h_col
        add(*_grid_boxes(_cuts(gx[0] - cxs / 2, gx[-1] + cxs / 2, (), bs),
                         _cuts(gy[0] - cys / 2, gy[-1] + cys / 2, (), bs),
                         np.array([zs, zs + cfg.slab_thickness])), "slab", s)
    if cfg.foundation > 0.0:     # last, so the building's block numbers do not depend on it
        add(np.array([[gx[0] - cxs / 2, gy[0] - cys / 2, oz - cfg.foundation]]),
            np.array([[gx[-1] + cxs / 2, gy[-1] + cys / 2, oz]]), "foundation", -1)
    return (np.concatenate(los), np.concatenate(his), np.concatenate(kinds),
            np.concatenate(storeys))


def build_building(cfg: StructureConfig, material_index: int = 0,
                   material_density: float | None = None) -> Structure:
    """The building of ``cfg`` as blocks with surface spheres and the faces to bond.

    ``material_index`` is the position of ``cfg.material`` in the DEM material table;
    ``material_density`` that material's density, used when ``cfg.density`` is null."""
    density = cfg.density if cfg.density is not None else material_density
    if density is None:
        raise ConfigError("key 'dem.structure.density' is null and no material density was given")
    lo, hi, kind, storey = building_boxes(cfg)
    # the fixed foundation needs spheres only where debris may land on it, and the ground plane
    # is there too: one per block_size instead of the members' 2 r keeps it from adding ~1,000
    spacing = np.where(kind == KINDS.index("foundation"), max(cfg.block_size, 2 * cfg.sphere_radius), np.nan)
    return assemble(lo, hi, density=density, sphere_radius=cfg.sphere_radius,
                    material=material_index, kind=kind, storey=storey, spacing=spacing)


# The paper's building (§4(4)): 208 blocks, sphere radius 0.1 m, σ_c = 1.0e7 Pa, δ_f = 0.02 m.
# The paper gives neither plan nor members; this is our documented equivalent (docs/cohesive.md,
# docs/img/building_paper.png): two storeys of 3.5 m, one 5 m bay along the flow (x), one 3 m
# bay across it, 0.4 m columns, 0.2 m walls on all sides, 0.2 m slabs, a 1.2 m × 2.0 m door in
# the ground-floor front wall (facing −x), blocks of at most 1 m: 32 + 128 + 48 = 208 blocks.
# It is the ``dem.cohesive`` / ``dem.structure`` content of a case file.
PAPER_BUILDING = {
    "cohesive": {"sigma_c": 1.0e7, "delta_f": 0.02, "mode": "reversible", "points_per_edge": 2},
    "structure": {
        "origin": [0.0, 0.0, 0.0], "storeys": 2, "storey_height": 3.5, "bays_x": [5.0],
        "bays_y": [3.0], "column": [0.4, 0.4], "wall_thickness": 0.2,
        "walls": ["xmin", "xmax", "ymin", "ymax"], "slab_thickness": 0.2,
        "openings": [{"storey": 0, "side": "xmin", "bay": 0, "offset": 0.7, "width": 1.2,
                      "sill": 0.0, "height": 2.0}],
        "block_size": 1.0, "sphere_radius": 0.1, "material": "concrete", "density": 2400.0},
}


def paper_building() -> tuple[StructureConfig, CohesiveConfig]:
    """The preset :data:`PAPER_BUILDING`, validated by the strict loader."""
    from ..config.loader import build
    src = "fcm_fsi.dem.builder.PAPER_BUILDING"
    return (build(StructureConfig, PAPER_BUILDING["structure"], src, prefix="dem.structure"),
            build(CohesiveConfig, PAPER_BUILDING["cohesive"], src, prefix="dem.cohesive"))


def load_structure(path) -> tuple[StructureConfig, CohesiveConfig | None]:
    """Read ``dem.structure`` (and ``dem.cohesive`` if present) from a case file, strictly.

    Serves until the case schema carries these sections itself (docs/cohesive.md)."""
    from pathlib import Path

    from ..config.loader import build, read_yaml
    from ..config.structure import CohesiveConfig
    data = read_yaml(Path(path))
    dem = data.get("dem") or {}
    if "structure" not in dem:
        raise ConfigError(f"{path}: key 'dem.structure' is required")
    structure = build(StructureConfig, dem["structure"], str(path), prefix="dem.structure")
    cohesive = (build(CohesiveConfig, dem["cohesive"], str(path), prefix="dem.cohesive")
                if dem.get("cohesive") is not None else None)
    return structure, cohesive
