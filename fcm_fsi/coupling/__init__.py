"""fcm_fsi.coupling — the stages of the sub-cycled fluid ⇄ DEM step (SPEC §3, issue #8); the
step that runs them in order is ``simulation/coupled.CoupledModel``:
cut → fluid → exchange → DEM sub-steps → diagnostics, repeated by the implicit coupling.

- ``cut_stage.py``       (a) the blocks' level set, the cut, the wall velocity, pockets, hidden parts
- ``wall_motion.py``     the rigid motion the wall nodes get (per block or bonded cluster, blended)
- ``exchange.py``        (c) the fluid's load on the blocks and the momentum-exchange check
- ``added_mass.py``      the added-mass stabilisation (m̃ per block or from the flow's tensor)
- ``hidden_load.py``     the static load on the blocks' true surfaces and the hidden parts
- ``sealed_pockets.py``  vents and drains of the pockets the gap fill seals
- ``dem_side.py``        (d) the DEM half: level-set primitives of the blocks, the sub-cycled DEM
                         advance under the fluid load (impulse record), interface velocity, MPI check
- ``implicit.py``        the step's snapshot/restore and the implicit coupling's passes
- ``fixed_point.py``     the implicit coupling's fixed-point acceleration
- ``diagnostics.py``     the series columns and the health (energy bound) check
- ``body_output.py``     bodies.csv, bond_breaks.csv, member_loads.csv, the blocks' VTP
"""
