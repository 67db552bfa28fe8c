"""Codegen stage: the derived program -> C source -> a compiled, cached cffi module.

Input: :class:`modelgen.derive.dynamics.Equations` and friends.  Output: the
generated ``<name>.c``/``<name>.h`` and a built module described by a manifest
(:class:`~modelgen.codegen.pipeline.Generated`).  ``pipeline.generate`` runs
the whole line (derive, CSE, print, emit, build) and is the stage's front door.
"""
