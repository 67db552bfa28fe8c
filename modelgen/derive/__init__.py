"""Derive stage: a frozen ModelSpec -> a straight-line program of named intermediates.

Input: :class:`modelgen.model.spec.ModelSpec`.  Output: frozen results over a
:class:`~modelgen.derive.graph.Graph` — :class:`~modelgen.derive.kinematics.Kinematics`,
:class:`~modelgen.derive.dynamics.Equations` (A, h, tau, energies, poses), the
outputs a scene asks for, the Jacobian terms — that the codegen stage prints.
Nothing here knows of C, files or compilers.  See README.md in this folder.
"""
