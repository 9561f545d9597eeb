"""fcm_fsi.coupling — the sub-cycled fluid ⇄ DEM loop (SPEC §3, issue #8).

- ``dem_side.py``  the DEM half: level-set primitives of the blocks, sub-cycled DEM advance
                   under the fluid load (impulse record), interface velocity, MPI check
"""
