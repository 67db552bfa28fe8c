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

import os
from dataclasses import dataclass, field, fields, replace

from modelgen.errors import ArgumentTypeError, ModelError

#: how ``<name>_rhs`` computes q_ddot: ``crba`` builds A and b = tau - h and
#: solves A q_ddot = b (LDL^T in C); ``aba`` runs the articulated-body
#: algorithm (O(n), joint trees only); ``auto`` picks aba for joint trees
#: (see :func:`modelgen.codegen.pipeline.choose_formulation`), else crba.
FORMULATIONS = ("auto", "aba", "crba")

#: the conventions of frame velocities and Jacobians (Pinocchio's ``ReferenceFrame``,
#: see :mod:`modelgen.derive.frames`)
REFERENCES = ("local", "world", "local_world_aligned")


@dataclass(frozen=True)
class KinematicsOptions:
    """Which kinematic quantities to generate (``BuildOptions.kinematics``).

    Checked as it is made: ``frames`` a list or tuple of names (one name, a
    string, is one frame), the flags ``True`` or ``False`` (not ``"false"``, not
    1), ``reference`` one of :data:`REFERENCES`; :meth:`of` refuses unknown keys.

    >>> KinematicsOptions.of({"frames": ["tool0"], "com": True}).frames
    ('tool0',)
    >>> KinematicsOptions(frames="tool0").frames
    ('tool0',)
    """
    #: frame names (the model's ``frames:``): ``<name>_frame_poses``,
    #: ``_frame_velocities`` and ``_frame_jacobians`` compute exactly these
    frames: tuple = ()
    #: the convention of the generated velocities, Jacobians and bias accelerations,
    #: one of :data:`REFERENCES`, Pinocchio's: ``local`` (the frame's axes, at its origin), ``world`` (E's axes,
    #: at O) or ``local_world_aligned`` (E's axes, at the frame's origin); Python
    #: converts to the others (see :mod:`modelgen.derive.frames`)
    reference: str = "local_world_aligned"
    #: also ``<name>_frame_bias_accelerations`` (the classical acceleration of
    #: each frame with q_ddot = 0, Pinocchio's getFrameClassicalAcceleration)
    bias_acceleration: bool = True
    #: also ``<name>_com`` and ``<name>_com_jacobian``
    com: bool = False
    #: also ``<name>_centroidal_momentum_matrix`` (Pinocchio's computeCentroidalMap)
    centroidal: bool = False

    def __post_init__(self):
        object.__setattr__(self, "frames", _frame_names(self.frames))
        for f in fields(self):
            if isinstance(f.default, bool):
                object.__setattr__(self, f.name, _flag(f.name, getattr(self, f.name),
                                                       f"kinematics option {f.name!r}"))
        if self.reference not in REFERENCES:
            raise ModelError(f"unknown frame reference {self.reference!r}",
                             key="kinematics.reference", fix="use one of " + ", ".join(REFERENCES))

    @classmethod
    def of(cls, value) -> KinematicsOptions | None:
        """:meth:`parse`, or None when nothing is asked (no frame, no com, no
        centroidal map)."""
        made = cls.parse(value)
        return made if made.frames or made.com or made.centroidal else None

    @classmethod
    def parse(cls, value) -> KinematicsOptions:
        """A KinematicsOptions from itself, a mapping of its fields, a list of frame
        names or one name; the defaults for None."""
        if value is None:
            return cls()
        if isinstance(value, cls):
            return value
        if isinstance(value, dict):
            known = [f.name for f in fields(cls)]
            unknown = [k for k in value if k not in known]
            if unknown:
                raise ArgumentTypeError(f"unknown kinematics option {unknown[0]!r}; fix: use "
                                        "the options " + ", ".join(known))
            return cls(**value)
        if isinstance(value, (list, tuple, str)):
            return cls(frames=value)
        raise ArgumentTypeError(f"kinematics must be a KinematicsOptions, a dict or a list "
                                f"of frame names, not {type(value).__name__}; fix: "
                                "kinematics={'frames': ['tool0'], 'com': True}")


def _flag(name: str, value, label: str = "") -> bool:
    """A yes/no option ``name`` (``label`` in the message, default the name): True or
    False (or numpy's), never a truthy string such as ``"no"``."""
    if isinstance(value, bool):
        return value
    if getattr(value, "dtype", None) is not None and value.dtype.kind == "b" and not value.shape:
        return bool(value)
    raise ArgumentTypeError(f"{label or name} must be True or False, got {value!r}; fix: "
                            f"{name}=True or {name}=False")


def _frame_names(frames) -> tuple:
    """``frames`` as a tuple of names: one name (a string) is one frame."""
    if isinstance(frames, str):
        return (frames,)
    if not (isinstance(frames, (list, tuple)) and all(isinstance(f, str) for f in frames)):
        raise ArgumentTypeError(f"kinematics option 'frames' must be a frame name or a list "
                                f"of frame names, got {frames!r}; fix: frames=['tool0', ...]")
    return tuple(frames)


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
    #: also generate ``<name>_derivatives`` (dqdd/dq, dqdd/dv, dqdd/du) and
    #: ``<name>_inverse_dynamics_derivatives`` (dQ/dq, dQ/dv, M): RNEA's derivatives
    #: (:mod:`modelgen.derive.rnea_partials` for a joint tree, else
    #: :mod:`modelgen.derive.rnea_derivatives`), solved with the mass matrix
    derivatives: bool = False
    #: the outputs of a scene (:class:`~modelgen.model.spec.OutputSpec`, a tuple):
    #: ``<name>_outputs`` computes exactly these
    outputs: tuple = ()
    #: read a URDF's root link as a free body (a free joint ``root_joint``).  It
    #: acts when the file is read (``as_spec(source, floating_base=...)``), so the
    #: spec, which the model hash covers, already shows it: ``key_text(read=False)``
    #: leaves it out, and a key made from the file's bytes includes it
    floating_base: bool = field(default=False, metadata={"read": True})
    #: the frame kinematics, centre of mass and centroidal map to generate
    #: (:class:`KinematicsOptions`, or None: none)
    kinematics: KinematicsOptions | None = None
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
        object.__setattr__(self, "kinematics", KinematicsOptions.of(self.kinematics))
        for f in fields(self):
            if isinstance(f.default, bool):
                object.__setattr__(self, f.name, _flag(f.name, getattr(self, f.name)))
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


#: Default budget, in operations after CSE (sin and cos weighted).  Calibrated on
#: gcc 12 (the levels and parts of build.OPT_LEVELS), 2-core machine shared with
#: other work: the 100-link spatial chain costs 196k, 297k with its derivatives
#: (generated in 28 s of CPU); the 150-link chain 336k (refused: its derivation
#: and CSE alone take about a minute).  Sums of ``c*sin(k*q)*cos(q)`` terms on a
#: one-coordinate pendulum, the costliest C per operation (every sin inline):
#: 206k weighted compile in 18 s of compiler CPU, 247k in 21 s, 384k in 34 s
#: (58 s of wall at load 5).  320k admits the 100-link chain with its derivatives
#: and keeps a build's compile under a minute on such a machine.
MAX_OPERATIONS = 320_000
ENV = "MODELGEN_MAX_OPERATIONS"


def max_operations(value: int | None = None) -> int:
    """The budget: ``value``, else ``$MODELGEN_MAX_OPERATIONS``, else
    :data:`MAX_OPERATIONS`; a ModelError if it is not a positive integer.

    >>> max_operations(1000)
    1000
    """
    source = "max_operations"
    if value is None:
        text = os.environ.get(ENV, "").strip()
        if not text:
            return MAX_OPERATIONS
        source = f"${ENV}"
        try:
            value = int(text.replace("_", ""))
        except ValueError:
            value = text
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise ModelError(f"{source} must be a positive integer, got {value!r}", key=source,
                         fix=f"give a number of operations, e.g. {MAX_OPERATIONS}")
    return value
