"""Codegen stage: the derived program -> C source -> a compiled, cached shared library.

Input: :class:`modelgen.derive.dynamics.Equations` and friends.  Output: the
generated ``<name>.c``/``<name>.h`` and a built library described by a manifest
(:class:`~modelgen.codegen.pipeline.Generated`); Python calls it through the one
runtime module (:func:`build.runtime_module`).  ``pipeline.generate`` runs
the whole line (derive, CSE, print, emit, build) and is the stage's front door.
"""
