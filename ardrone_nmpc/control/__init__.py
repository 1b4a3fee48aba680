"""High-level controllers and the command mapping.

* ``solver``: :func:`make_nmpc`, the NMPC solver a config names — ``cgmres`` or ``newton``
  (thesis ch. 3, C/GMRES) over ``solver_base``, the ``kernels`` package and ``gmres``;
  ``ocp`` is the problem as data.
* ``proportional``: the baseline P controller of thesis eq. 4.16.
* ``mapping``: u = [z̈, φ, θ, ψ̇] → AR.Drone PCMD fractions (docs/design.md).

Import the submodules directly; this package deliberately imports nothing so that the light
modules (P controller, mapping) do not pull in the solver kernels.
"""
