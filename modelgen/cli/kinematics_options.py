"""The frame kinematics options of ``modelgen generate`` (``--frame``, ``--com``,
``--centroidal``, ``--reference``, ``--no-bias-acceleration``): the fields of
:class:`~modelgen.codegen.options.KinematicsOptions`, so that a C user gets the
functions docs/kinematics.md describes without Python."""
from __future__ import annotations

from modelgen.codegen.options import REFERENCES, KinematicsOptions
from modelgen.errors import ModelgenError


def add_kinematics_options(parser) -> None:
    """The options, in a group of their own in ``--help``."""
    group = parser.add_argument_group(
        "frame kinematics",
        "also generate <name>_frame_poses, _frame_velocities, _frame_jacobians and "
        "_frame_bias_accelerations for the frames given, <name>_com and _com_jacobian, "
        "<name>_centroidal_momentum_matrix (see docs/kinematics.md)")
    group.add_argument("--frame", action="append", dest="frames", metavar="NAME",
                       help="a frame of the model (its 'frames:'; a URDF's links and fixed "
                            "joints); repeatable, in the order of the C arrays")
    group.add_argument("--com", action="store_true",
                       help="the centre of mass and its Jacobian")
    group.add_argument("--centroidal", action="store_true",
                       help="the centroidal momentum matrix")
    group.add_argument("--reference", choices=REFERENCES, default=None,
                       help="convention of the frames' velocities, Jacobians and bias "
                            "accelerations (default local_world_aligned)")
    group.add_argument("--no-bias-acceleration", action="store_true",
                       help="leave out <name>_frame_bias_accelerations")


def kinematics_of(args) -> KinematicsOptions | None:
    """The KinematicsOptions the options ask for (None: none).  --reference and
    --no-bias-acceleration shape the frames' functions: without --frame they are refused
    rather than ignored."""
    frames = tuple(dict.fromkeys(args.frames or ()))
    if not frames:
        for flag, given in (("--reference", args.reference is not None),
                            ("--no-bias-acceleration", args.no_bias_acceleration)):
            if given:
                raise ModelgenError(f"{flag} applies to the frames' functions, and no frame "
                                    f"is asked for; fix: add --frame NAME (repeatable)")
    return KinematicsOptions.of({
        "frames": frames,
        "reference": args.reference or KinematicsOptions.reference,
        "bias_acceleration": not args.no_bias_acceleration,
        "com": args.com, "centroidal": args.centroidal})


def kinematics_line(info: dict) -> str:
    """What ``generate`` says of a build's kinematics (its manifest's entry)."""
    parts = []
    if info["frames"]:
        parts.append(f"frames {', '.join(info['frames'])} ({info['reference']}"
                     + (", with bias accelerations)" if info["bias_acceleration"] else ")"))
    parts += [words for key, words in (("com", "centre of mass"),
                                       ("centroidal", "centroidal momentum matrix"))
              if info.get(key)]
    return "; ".join(parts)
