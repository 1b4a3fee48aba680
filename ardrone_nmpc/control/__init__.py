"""High-level controllers and the command mapping.

* ``gmres``, ``cgmres``, ``newton``: the NMPC solvers (thesis ch. 3, C/GMRES).
* ``proportional``: the baseline P controller of thesis eq. 4.16.
* ``mapping``: u = [z̈, φ, θ, ψ̇] → AR.Drone PCMD fractions (DESIGN.md §4).

Import the submodules directly; this package deliberately imports nothing so that the light
modules (P controller, mapping) do not pull in the solver kernels.
"""
