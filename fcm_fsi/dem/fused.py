"""One Numba pass over the blocks for the rest of a DEM step after the pair kernel.

When a :class:`~fcm_fsi.dem.system.DEMSystem` has only sphere–sphere contact (and walls),
no controls and no ledger — the pure-DEM production case and the throughput benchmark —
:meth:`DEMSystem.step` runs the step as

1. the Verlet check (rebuild if needed) and the pair kernel (``contact.pair_forces``: one
   parallel loop over the pairs), then
2. :func:`advance_blocks`: one parallel loop over the blocks that, per block, zeroes its
   force and torque, gathers its pair forces, adds its sphere–wall contacts, gravity and the
   external load, kicks, drifts and moves its spheres.

Everything block b's step needs is block b's own data (the pair forces were computed
before), so this is race-free; each operation is the same arithmetic in the same order as
the stage-by-stage path (``compute_forces``, ``kick``, ``drift``,
``update_sphere_positions``), so the two paths agree bit for bit in the state
(tests/dem/test_dem_fused.py; only the summation order of the ledger energies differs).

The per-block work is a plain (serial) function over a range of blocks, called on
``CHUNKS`` contiguous ranges in parallel: the parallel kernel stays small (quick to
compile) and the call overhead is paid once per range, not once per block.
"""
from __future__ import annotations

import numba as nb
import numpy as np

from .bodies import _place_block_spheres
from .contact import _gather_block
from .integrate import _drift_block, _kick_block
from .wall_contact import _block_walls

CHUNKS = 64   # block ranges per step (each thread takes CHUNKS / threads of them)


@nb.njit(cache=True)
def _advance_range(b0, b1, blk_sph_start, sph_pos, sph_radius, sph_material, sph_local,
                   pos, quat, vel, omega, angmom, mass, inv_mass, inertia, fixed, ext_force, ext_torque, gravity,
                   sp_start, sp_pair, sp_sign, act, pair_f, pair_x,
                   planes, plane_mat, tris, tri_mesh, mesh_mat, nmesh, active, whist, wheld, wtab, clip,
                   planar, dt, force, torque):
    e_s = 0.0
    d_d = 0.0
    d_f = 0.0
    for b in range(b0, b1):
        for d in range(3):
            force[b, d] = 0.0
            torque[b, d] = 0.0
        _gather_block(b, blk_sph_start, pos, sp_start, sp_pair, sp_sign, act, pair_f, pair_x, force, torque)
        if not fixed[b]:
            es, dd, df = _block_walls(b, blk_sph_start, sph_pos, sph_radius, sph_material, pos, vel, omega, mass,
                                      planes, plane_mat, tris, tri_mesh, mesh_mat, nmesh, active, whist, wheld,
                                      wtab, clip, dt, force, torque)
            e_s += es
            d_d += dd
            d_f += df
        for d in range(3):
            force[b, d] += mass[b] * gravity[d]
        for d in range(3):
            force[b, d] += ext_force[b, d]
        for d in range(3):
            torque[b, d] += ext_torque[b, d]
        if not fixed[b]:
            _kick_block(b, vel, angmom, mass, inv_mass, force, torque, planar, dt)
            _drift_block(b, pos, quat, vel, angmom, omega, inertia, dt)
        _place_block_spheres(b, pos, quat, blk_sph_start, sph_local, sph_pos)
    return e_s, d_d, d_f


@nb.njit(cache=True, parallel=True)
def advance_blocks(blk_sph_start, sph_pos, sph_radius, sph_material, sph_local,
                   pos, quat, vel, omega, angmom, mass, inv_mass, inertia, fixed, ext_force, ext_torque, gravity,
                   sp_start, sp_pair, sp_sign, act, pair_f, pair_x,
                   planes, plane_mat, tris, tri_mesh, mesh_mat, nmesh, active, whist, wheld, wtab, clip,
                   planar, dt, force, torque):
    """Forces (pair gather, walls, gravity, external), kick, drift and sphere positions of
    every block (module docstring). force/torque receive this step's totals (as
    ``DEMSystem.force``/``torque`` on the stage-by-stage path); ``planar`` as in
    ``integrate.kick``. Returns the walls' (spring
    energy, dashpot loss, slider loss)."""
    nbk = pos.shape[0]
    nch = min(CHUNKS, nbk)
    part = np.zeros((max(nch, 1), 3))
    for c in nb.prange(nch):
        r = _advance_range(c * nbk // nch, (c + 1) * nbk // nch, blk_sph_start, sph_pos, sph_radius, sph_material,
                           sph_local, pos, quat, vel, omega, angmom, mass, inv_mass, inertia, fixed, ext_force, ext_torque,
                           gravity, sp_start, sp_pair, sp_sign, act, pair_f, pair_x, planes, plane_mat, tris,
                           tri_mesh, mesh_mat, nmesh, active, whist, wheld, wtab, clip, planar, dt, force, torque)
        part[c, 0] = r[0]
        part[c, 1] = r[1]
        part[c, 2] = r[2]
    return part[:, 0].sum(), part[:, 1].sum(), part[:, 2].sum()
