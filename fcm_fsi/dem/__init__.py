"""fcm_fsi.dem — clumped-sphere rigid blocks with spring–dashpot–slider contact (SPEC §2).

Layout of the package (data flow top to bottom):

- ``state.py``       :class:`DEMState`, the struct-of-arrays state (layout and units there)
- ``bodies.py``      mass properties (box, clump), quaternion constructors
                     (rotations: ``fcm_fsi/geometry.py``)
- ``neighbours.py``  cell list → Verlet pair list with skin
- ``contact.py``     the contact law (eqs 18–20) and the sphere–sphere kernels
- ``wall_contact.py`` sphere–wall contact (planes, triangle meshes) with the same law
- ``contact_reference.py`` NumPy twins of the contact kernels (tests)
- ``walls.py``       the case's static walls, read once: for the wall contact and the
                     fluid's gap fill
- ``laws.py``        the registry of contact laws (which ones the fused step implements)
- ``integrate.py``   leapfrog translation + split free-rotor rotation (eqs 25–27)
- ``control.py``     prescribed displacement / velocity / force per block and DOF
- ``ledger.py``      energy ledger
- ``system.py``      :class:`DEMSystem`: one step = a short list of named stages
- ``model.py``       :class:`DEMSystem` from a ``DEMConfig`` (time-step check)
- ``output.py``      VTK PolyData (.vtp + .pvd) of the spheres

The interaction hook (contract for contact, cohesive bonds and anything else that
produces forces between or on blocks)
----------------------------------------------------------------------------------
:class:`fcm_fsi.dem.system.DEMSystem` holds a list ``system.interactions``. Each DEM step
it zeroes ``force (nb,3)``, ``torque (nb,3)`` and ``ledger (LEDGER_SLOTS,)`` and calls,
in list order::

    interaction.add_forces(state, force, torque, ledger, dt)

An interaction must

1. ADD (never assign) into ``force[b]`` [N] and ``torque[b]`` [N m, about the centre of
   mass ``state.pos[b]``, world frame] of the blocks it acts on. Gravity, external
   inputs and control are added by the system itself, not by interactions;
2. ADD its current *stored* energy [J] into ``ledger[L_SPRING]`` (contact springs) or
   ``ledger[L_BOND]`` (cohesive bonds), and the energy it *dissipated during this step*
   [J, >= 0] into ``ledger[L_DASHPOT]``, ``ledger[L_FRICTION]`` or ``ledger[L_BOND_LOSS]``.
   The :class:`~fcm_fsi.dem.ledger.Ledger` sums the increments over time;
3. read, not write, the state: at the call, ``state.pos``, ``state.quat`` and
   ``state.sph_pos`` are at step n, ``state.vel`` / ``state.omega`` are the leapfrog
   half-step velocities n − 1/2 (the velocity of a material point x of block b is
   ``vel[b] + omega[b] × (x − pos[b])``). History variables (tangential springs,
   bond damage) are the interaction's own arrays, updated inside ``add_forces``;
4. do the work in Numba kernels that take arrays only (each with a NumPy reference);
5. optionally provide ``checkpoint_arrays() -> dict[str, ndarray]`` and
   ``restore(arrays)`` so a restart is bit-identical (the driver stores them under
   ``interaction_<k>`` in the checkpoint), and ``stiffness_bound()`` → ``(k_max [N/m], h)``
   used for the stable time step check Δt_cr (``DEMSystem.critical_time_step``).

Register it with ``system.interactions.append(obj)``; the integrator is not edited.
"""
from __future__ import annotations

L_SPRING = 0      # stored elastic energy of contact springs (normal + tangential) [J]
L_DASHPOT = 1     # dashpot dissipation during this step [J]
L_FRICTION = 2    # Coulomb-slider dissipation during this step [J]
L_BOND = 3        # stored elastic energy of cohesive bonds [J]
L_BOND_LOSS = 4   # energy dissipated by bonds during this step (damage, bond dashpots) [J]
LEDGER_SLOTS = 5

__all__ = ["L_SPRING", "L_DASHPOT", "L_FRICTION", "L_BOND", "L_BOND_LOSS", "LEDGER_SLOTS"]
