"""Build options: what, besides the model, decides what is generated and built.

One frozen :class:`BuildOptions` travels from the front doors
(``modelgen.load``, ``generate_model``, ``load_scene``, the CLI) to
:func:`modelgen.codegen.pipeline.generate`; its :meth:`BuildOptions.key_text`
is the only place the options enter the model hash and so the build key.

This module imports nothing heavy: the cache lookup reads it before (and
often instead of) the symbolic pipeline.

Adding an option is one line: a field with a default.  A field at its
default adds nothing to the key (so existing builds keep their key); a
``True`` flag adds its name, any other value its ``repr``.  A field that
acts when the model file is read (not on the spec) is marked
``metadata={"read": True}``.
"""
from __future__ import annotations

from dataclasses import dataclass, field, fields, replace

#: how ``<name>_rhs`` computes q_ddot: ``crba`` builds A and b = tau - h and
#: solves A q_ddot = b (LDL^T in C); ``aba`` runs the articulated-body
#: algorithm (O(n), joint trees only); ``auto`` picks aba for joint trees
#: (see :func:`modelgen.codegen.pipeline.choose_formulation`), else crba.
FORMULATIONS = ("auto", "aba", "crba")


@dataclass(frozen=True)
class BuildOptions:
    """How to build a model (the model itself is the spec).

    >>> BuildOptions(linearize=True).jacobian          # linearize implies jacobian
    True
    >>> BuildOptions.of(None, formulation="crba") == BuildOptions(formulation="crba")
    True
    """
    #: how the rhs computes q_ddot, one of :data:`FORMULATIONS`; ``auto`` is
    #: resolved by ``generate`` and the resolved value is what the key holds
    formulation: str = "auto"
    #: also generate ``<name>_jacobian``, the symbolic d(xdot)/dx (for stiff
    #: integrators; it costs generation and compile time)
    jacobian: bool = False
    #: also generate ``<name>_linearize`` (A, B, C, D); implies ``jacobian``
    linearize: bool = False
    #: the outputs of a scene (:class:`~modelgen.model.spec.OutputSpec`, a tuple):
    #: ``<name>_outputs`` computes exactly these
    outputs: tuple = ()
    #: read a URDF's root link as a free body (a free joint ``root_joint``).  It
    #: acts when the file is read (``as_spec(source, floating_base=...)``), so the
    #: spec, which the model hash covers, already shows it: ``key_text(read=False)``
    #: leaves it out, and a key made from the file's bytes includes it
    floating_base: bool = field(default=False, metadata={"read": True})
    #: how a URDF's bodies that no rigid body matches are read: ``physical``
    #: (refused), ``as_is`` (kept, with a warning) or ``balance`` (MuJoCo's
    #: balanceinertia); see :func:`modelgen.model.urdf.import_urdf_text`
    inertia: str = field(default="physical", metadata={"read": True})
    #: MuJoCo's boundmass and boundinertia for a URDF's moving links
    min_mass: float = field(default=0.0, metadata={"read": True})
    min_inertia: float = field(default=0.0, metadata={"read": True})
    #: ``ignore``: a URDF's ``<mimic>`` tags are dropped, each joint its own
    #: coordinate (Pinocchio's mimic=False); ``strict`` follows them
    mimic: str = field(default="strict", metadata={"read": True})

    def reading(self) -> dict:
        """The fields that act when the model file is read, as ``as_spec`` keywords."""
        return {f.name: getattr(self, f.name) for f in fields(self) if f.metadata.get("read")}

    def __post_init__(self):
        object.__setattr__(self, "outputs", tuple(self.outputs))
        for f in fields(self):
            if isinstance(f.default, bool):
                object.__setattr__(self, f.name, bool(getattr(self, f.name)))
        if self.linearize:
            object.__setattr__(self, "jacobian", True)

    @classmethod
    def of(cls, options: BuildOptions | None = None, **shorthand) -> BuildOptions:
        """``options`` (default: the defaults) with the shorthand keywords that are
        not None (``jacobian=True``...) put in; what the public functions call."""
        base = options if options is not None else cls()
        given = {k: v for k, v in shorthand.items() if v is not None}
        return replace(base, **given) if given else base

    def key_text(self, read: bool = True) -> str:
        """The options as a key: the outputs and the fields not at their default, then
        (after a NUL) the formulation.  ``read=False`` leaves out the fields that act
        when the model file is read (the model hash has the spec they made)."""
        text = repr(self.outputs)
        for f in fields(self):
            if f.name in ("outputs", "formulation") or (not read and f.metadata.get("read")):
                continue
            value = getattr(self, f.name)
            if value == f.default:
                continue
            text += f" {f.name}" if value is True else f" {f.name}={value!r}"
        return f"{text}\0{self.formulation}"
