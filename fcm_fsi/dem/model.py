"""A :class:`DEMSystem` from a ``DEMConfig``: blocks, generators, walls (``walls.py``), the
contact law (``laws.py``), controls, and the stable-time-step check (tutorial §6)."""
from __future__ import annotations

import dataclasses
import math

import numpy as np

from ..config.dem import BlockConfig, DEMConfig, GeneratorConfig
from ..config.loader import ConfigError
from ..geometry import quat_to_matrix_np
from ..io.logging import get_logger
from .bodies import BlockTemplate, axis_angle_quat, box_template, clump_template, matrix_to_quat
from .cohesive import BondFace, CohesiveBonds, CohesiveLaw
from .contact import Materials
from .control import Control, Controls
from .grid_fill import grid_fill
from .laws import DEFAULT_LAW, LAWS
from .mesh_block import mesh_block
from .restitution import damping_ratio
from .state import DEMState
from .system import DEMSystem
from .walls import walls_of

log = get_logger("dem")


def described_blocks(cfg: DEMConfig) -> list[tuple[str, BlockConfig, int]]:
    """(key, block description, number of blocks) in the state's block order (``build_state``):
    dem.blocks one by one (a bonded grid as its pieces), then each generator's template
    ``count`` times; the structure's blocks come after these."""
    out = []
    for i, b in enumerate(cfg.blocks):
        count = len(grid_fill_of(cfg, i).pieces) if b.fill == "bonded_grid" else 1
        out.append((f"dem.blocks[{i}]", b, count))
    out += [(f"dem.generators[{i}].block", g.block, g.count) for i, g in enumerate(cfg.generators)]
    return out


def grid_fill_of(cfg: DEMConfig, entry: int | str):
    """The pieces and bonds of ``dem.blocks[i]`` (fill bonded_grid; dem/grid_fill.py); ``entry``
    the index i or the key of :func:`described_blocks`."""
    i = entry if isinstance(entry, int) else int(entry[len("dem.blocks["):-1])
    b = cfg.blocks[i]
    return grid_fill(b, cfg.materials[cfg.material_index(b.material)].density, cfg.cohesive.points_per_edge,
                     f"dem.blocks[{i}]")


def template_of(b: BlockConfig, density: float, key: str = "dem.blocks[]") -> BlockTemplate:
    """Mass properties and spheres of one block description (principal frame); ``key`` names
    the block in errors about its file (shape mesh)."""
    if b.shape == "mesh":
        return mesh_block(b, density, key).template
    if b.shape == "box":
        return box_template(b.size, density, b.radius, b.spacing)
    if b.shape == "sphere":
        return clump_template([[0.0, 0.0, 0.0]], [b.radius], density)
    s = np.asarray(b.spheres, np.float64)
    return clump_template(s[:, :3], s[:, 3], density)


def materials_of(cfg: DEMConfig) -> Materials:
    m = cfg.materials
    return Materials([x.stiffness for x in m], [x.stiffness * x.tangential_ratio for x in m],
                     [damping_ratio(x.restitution) for x in m], [x.mu for x in m])


def _generated(g: GeneratorConfig, tmpl: BlockTemplate) -> tuple[np.ndarray, np.ndarray]:
    """Positions (count, 3) on a jittered cubic lattice and orientations (count, 4)."""
    rng = np.random.default_rng(g.seed)
    R = float(np.max(np.linalg.norm(tmpl.sph_local, axis=1) + tmpl.sph_radius))
    a = 2.0 * R * 1.05
    lo, hi = np.asarray(g.region_min) + 1.05 * R, np.asarray(g.region_max) - 1.05 * R   # room for the jitter
    n = np.maximum(np.floor((hi - lo) / a).astype(int) + 1, 1)
    if np.any(hi < lo) or np.prod(n) < g.count:
        raise ConfigError(f"key 'dem.generators[].count' = {g.count} blocks of bounding radius {R:.4g} m "
                          f"do not fit in region {g.region_min}..{g.region_max} "
                          f"(room for {int(np.prod(n)) if np.all(hi >= lo) else 0})")
    idx = np.arange(g.count)
    ijk = np.stack([idx % n[0], (idx // n[0]) % n[1], idx // (n[0] * n[1])], axis=1)
    pos = lo + a * ijk + rng.uniform(-0.02 * R, 0.02 * R, size=(g.count, 3))
    if g.random_orientation:
        q = rng.normal(size=(g.count, 4))
        q /= np.linalg.norm(q, axis=1)[:, None]
    else:
        q = np.tile([1.0, 0.0, 0.0, 0.0], (g.count, 1))
    return pos, q


def _qmul(p, q):
    w1, v1, w2, v2 = p[0], p[1:], q[0], q[1:]
    return np.concatenate([[w1 * w2 - v1 @ v2], w1 * v2 + w2 * v1 + np.cross(v1, v2)])


def build_structure(cfg: DEMConfig):
    """The bonded building of ``dem.structure`` (None when absent)."""
    if cfg.structure is None:
        return None
    from .builder import build_building
    k = cfg.material_index(cfg.structure.material)
    return build_building(cfg.structure, k, cfg.materials[k].density)


def build_state(cfg: DEMConfig, structure=None) -> DEMState:
    """All blocks (cfg.blocks, then generated, then the structure's) as a DEMState."""
    pos, quat, mass, inertia, vel, omega, fixed = [], [], [], [], [], [], []
    sb, sl, sr, sm = [], [], [], []

    def add(tmpl: BlockTemplate, b: BlockConfig, p, q_user, p_is_com: bool = False):
        k = len(pos)
        # principal frame → user frame is R_body; world = q_user ∘ R_body
        q = _qmul(q_user, matrix_to_quat(tmpl.R_body))
        origin_shift = tmpl.R_body @ np.zeros(3)
        if b.shape == "clump" and not p_is_com:   # spheres given relative to `position`: move to the com
            s = np.asarray(b.spheres)[:, :3]
            ms = s[:, 0] * 0 + np.asarray(b.spheres)[:, 3] ** 3
            origin_shift = (ms[:, None] * s).sum(0) / ms.sum()
        if b.shape == "mesh" and not p_is_com:    # the file's origin at `position`: move to the com
            origin_shift = tmpl.com
        pos.append(np.asarray(p) + quat_to_matrix_np(np.asarray(q_user)) @ origin_shift)
        quat.append(q)
        mass.append(tmpl.mass)
        inertia.append(tmpl.inertia)
        vel.append(b.velocity)
        omega.append(b.omega)
        fixed.append(b.fixed)
        sb.extend([k] * len(tmpl.sph_radius))
        sl.extend(tmpl.sph_local)
        sr.extend(tmpl.sph_radius)
        sm.extend([cfg.material_index(b.material)] * len(tmpl.sph_radius))

    for i, b in enumerate(cfg.blocks):
        dens = cfg.materials[cfg.material_index(b.material)].density
        q_user = axis_angle_quat(b.axis, math.radians(b.angle))
        if b.fill == "bonded_grid":             # each piece: the file's origin at `position`
            for piece in grid_fill_of(cfg, i).pieces:
                add(piece.template, b, b.position, q_user)
        else:
            add(template_of(b, dens, f"dem.blocks[{i}]"), b, b.position, q_user)
    for i, g in enumerate(cfg.generators):
        dens = cfg.materials[cfg.material_index(g.block.material)].density
        tmpl = template_of(g.block, dens, f"dem.generators[{i}].block")
        P, Q = _generated(g, tmpl)
        for p, q in zip(P, Q):
            add(tmpl, g.block, p, q, p_is_com=True)
    if structure is not None:
        first = len(pos)
        pos.extend(structure.pos)
        quat.extend(structure.quat)
        mass.extend(structure.mass)
        inertia.extend(structure.inertia)
        vel.extend(np.zeros((structure.nb, 3)))
        omega.extend(np.zeros((structure.nb, 3)))
        fixed.extend(structure.fixed)
        sb.extend(structure.sph_block + first)
        sl.extend(structure.sph_local)
        sr.extend(structure.sph_radius)
        sm.extend(structure.sph_material)
    return DEMState.from_blocks(pos, quat, mass, inertia, sb, sl, sr, sm, vel=vel, omega=omega, fixed=fixed)


def build_system(cfg: DEMConfig, with_ledger: bool = True, structure=None, law: str = DEFAULT_LAW) -> DEMSystem:
    """Blocks, contact, walls, controls; refuses dt > dt_safety·Δt_cr (ConfigError).
    ``structure``: the built ``dem.structure`` when the caller has it (built here otherwise);
    ``law``: the contact law, a name in :data:`~fcm_fsi.dem.laws.LAWS`."""
    if structure is None:
        structure = build_structure(cfg)
    state = build_state(cfg, structure)
    mats = materials_of(cfg)
    skin = cfg.skin if cfg.skin is not None else 0.3 * float(state.sph_radius.min())
    contact = LAWS[law]
    inter = [contact.spheres(mats, skin, cfg.clip_normal)]
    walls = contact.walls(walls_of(cfg), mats, state.ns, cfg.clip_normal)
    if walls is not None:
        inter.append(walls)
    bonds = cohesive_bonds(cfg, state, structure)
    if bonds is not None:
        inter.append(bonds)
    controls = None
    if cfg.controls:
        controls = Controls([Control(c.block, tuple(c.modes), tuple(c.values), c.ramp) for c in cfg.controls], state)
    system = DEMSystem(state, inter, cfg.dt, cfg.gravity, controls, with_ledger)
    check_time_step(system, cfg.dt_safety)
    return system


def bonded_block_faces(cfg: DEMConfig) -> list:
    """Faces shared by the ``bonded`` boxes of ``dem.blocks`` (block indices = their order there,
    which is their index in the state)."""
    from .builder import touching_faces
    idx = [i for i, b in enumerate(cfg.blocks) if b.bonded]
    if len(idx) < 2:
        return []
    centre = np.array([cfg.blocks[i].position for i in idx], float)
    half = 0.5 * np.array([cfg.blocks[i].size for i in idx], float)
    return [dataclasses.replace(f, a=idx[f.a], b=idx[f.b]) for f in touching_faces(centre - half, centre + half)]


def cohesive_bonds(cfg: DEMConfig, state: DEMState, structure=None):
    """One set of cohesive bonds on the faces of the bonded blocks and of the structure (its
    block indices shifted to the state's: it comes last), in the built, stress-free
    configuration; None when there are none."""
    faces = bonded_block_faces(cfg)
    points = [None] * len(faces)
    if structure is not None:
        first = state.nb - structure.nb
        faces += [dataclasses.replace(f, a=f.a + first, b=f.b + first) for f in structure.faces]
        points += [None] * len(structure.faces)
    for f, p in grid_bond_faces(cfg):
        faces.append(f)
        points.append(p)
    if not faces:
        return None
    return CohesiveBonds.from_faces(CohesiveLaw.from_config(cfg.cohesive), faces, state.pos, state.quat,
                                    cfg.cohesive.points_per_edge, points)


def grid_bond_faces(cfg: DEMConfig) -> list:
    """The bonds between the pieces of the bonded grids of ``dem.blocks``, in the world frame:
    (BondFace, (points (m, 3) [m], areas (m,) [m²])) with block indices in the state's order."""
    out, first = [], 0
    for key, b, count in described_blocks(cfg):
        if b.fill == "bonded_grid":
            fill = grid_fill_of(cfg, key)
            R = quat_to_matrix_np(axis_angle_quat(b.axis, math.radians(b.angle)))
            at = np.asarray(b.position, float)
            for g in fill.bonds:
                pts = at + g.points @ R.T
                n = R @ g.normal
                u = R @ np.roll(np.abs(g.normal), 1)
                area = float(g.areas.sum())
                face = BondFace(a=first + g.a, b=first + g.b, centre=tuple(pts.mean(axis=0)), normal=tuple(n),
                                axis_u=tuple(u), axis_v=tuple(np.cross(n, u)), half_u=0.5 * np.sqrt(area),
                                half_v=0.5 * np.sqrt(area))
                out.append((face, (pts, g.areas)))
        first += count
    return out


def check_time_step(system: DEMSystem, safety: float) -> float:
    """Refuse dt above safety·Δt_cr; log the margin. Returns Δt_cr."""
    dtc = system.critical_time_step()
    if system.dt > safety * dtc:
        raise ConfigError(f"key 'dem.dt' = {system.dt:.4g} s exceeds dt_safety × Δt_cr = {safety:g} × "
                          f"{dtc:.4g} s = {safety * dtc:.4g} s (Δt_cr = 2√(m/k)(√(h²+1) − h), lightest "
                          f"effective contact mass, stiffest contact; see docs/dem.md)")
    log.info("DEM time step %.4g s = %.3f Δt_cr (Δt_cr = %.4g s, allowed up to %.3g)", system.dt,
             system.dt / dtc, dtc, safety)
    return dtc
