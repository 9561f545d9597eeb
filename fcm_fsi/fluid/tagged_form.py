"""Compiled forms whose cell integrals follow cell tags that change during a run.

A dolfinx 0.5 form fixes the cells of each integral ``dx(i)`` when it is built. The cut fluid
domain (:mod:`fcm_fsi.fcm.domain`) integrates uncut cells with the plain rule and cut cells with
moment-fitted weights, and which cells are cut moves with the bodies. :class:`TaggedForm`
compiles the UFL form once (FFCx JIT, with :mod:`fcm_fsi.jit`'s flags) and rebuilds only the cheap C++ form object, with the
same kernels and coefficients, whenever the values of its cell tags have changed in place.
Use ``.form`` at assembly time; it is always current.
"""
from __future__ import annotations

import numpy as np
import ufl
from dolfinx import cpp, fem
from dolfinx import jit as dolfinx_jit
from petsc4py import PETSc

from .. import jit

_INTEGRAL_TYPES = {"cell": cpp.fem.IntegralType.cell, "exterior_facet": cpp.fem.IntegralType.exterior_facet,
                   "interior_facet": cpp.fem.IntegralType.interior_facet, "vertex": cpp.fem.IntegralType.vertex}


class TaggedForm:
    """A form compiled once; its C++ object is rebuilt when the cell tags' values change.

    ufl_form: the UFL form (real scalars). Cell integrals with a subdomain id read their cells
    from the form's cell ``subdomain_data`` (a MeshTags whose ``values`` the owner may
    overwrite in place; the indices must stay the same).
    """

    def __init__(self, ufl_form: ufl.Form) -> None:
        if PETSc.ScalarType != np.float64:
            raise NotImplementedError("TaggedForm supports real double-precision PETSc only")
        sd = ufl_form.subdomain_data()
        (domain,) = list(sd.keys())
        data = sd[domain]
        self.mesh = domain.ufl_cargo()
        params = {"scalar_type": "double"}
        self._ufcx, self._module, self._code = dolfinx_jit.ffcx_jit(self.mesh.comm, ufl_form, form_compiler_params=params,
                                                                    jit_params=jit.jit_parameters())
        self._spaces = [arg.ufl_function_space()._cpp_object for arg in ufl_form.arguments()]
        original = ufl_form.coefficients()
        self._coefficients = [original[self._ufcx.original_coefficient_position[i]]._cpp_object
                              for i in range(self._ufcx.num_coefficients)]
        self._constants = [c._cpp_object for c in ufl_form.constants()]
        self._subdomains = {t: data.get(name) for name, t in _INTEGRAL_TYPES.items()}
        self._cell_tags = data.get("cell")
        self._tag_values = None
        self._form = None
        self.rebuilds = 0   # how often the C++ form was rebuilt after the first build

    @property
    def form(self) -> fem.FormMetaClass:
        """The dolfinx form for the current cell tags."""
        tags = self._cell_tags
        if self._form is None or (tags is not None and not np.array_equal(tags.values, self._tag_values)):
            if self._form is not None:
                self.rebuilds += 1
            self._form = self._build()
            self._tag_values = None if tags is None else tags.values.copy()
        return self._form

    def _build(self) -> fem.FormMetaClass:
        cls = type("Form", (fem.FormMetaClass, cpp.fem.Form_float64), {})
        return cls(self._ufcx, self._spaces, self._coefficients, self._constants, self._subdomains,
                   self.mesh, self._module.ffi, self._code)
