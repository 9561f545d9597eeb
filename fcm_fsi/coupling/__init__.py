"""fcm_fsi.coupling — the stages of the sub-cycled fluid ⇄ DEM step (SPEC §3, issue #8); the
step that runs them in order is ``simulation/coupled.CoupledModel``.

- ``dem_side.py``        the DEM half: level-set primitives of the blocks, sub-cycled DEM
                         advance under the fluid load (impulse record), interface velocity, MPI check
- ``added_mass.py``      the added-mass stabilisation (m̃ per block or from the flow's tensor)
- ``hidden_load.py``     the static load on the blocks' true surfaces and the hidden parts
- ``sealed_pockets.py``  vents and drains of the pockets the gap fill seals
- ``body_output.py``     bodies.csv, bond_breaks.csv, member_loads.csv, the blocks' VTP
- ``fixed_point.py``     the implicit coupling's fixed-point acceleration
"""
