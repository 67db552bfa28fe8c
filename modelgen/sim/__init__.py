"""Sim stage: a compiled module -> numpy callables and trajectories.

Input: a build (:class:`modelgen.codegen.pipeline.Generated`).  Output:
:class:`~modelgen.sim.runtime.CompiledModel` (A, h, tau, rhs, energies, poses
as numpy-in, numpy-out calls; ``simulate`` with every C integrator),
:class:`~modelgen.sim.result.Result` (the one result type) and
:class:`~modelgen.sim.scene.Scene`.  ``load.py`` is the front door.
"""
