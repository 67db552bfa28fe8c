"""From a model source to a loaded :class:`CompiledModel` or :class:`Scene`: the front door.

These are the functions ``modelgen.load``, ``modelgen.load_scene`` and
``modelgen.generate_model`` re-export.

A model file built before is found through the build cache's fast index
(:mod:`modelgen.codegen.index`: the file's bytes and the options), without
importing the model reader or the symbolic pipeline; those are imported
inside the functions below, only when the index has no verified build.
"""
from __future__ import annotations

import importlib
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

from modelgen.codegen import index
from modelgen.codegen.build import Generated
from modelgen.codegen.options import BuildOptions, KinematicsOptions
from modelgen.codegen.options import max_operations as max_operations_of
from modelgen.errors import ArgumentTypeError
from modelgen.sim import massmatrix
from modelgen.sim.library import mass_matrix_function

if TYPE_CHECKING:
    from modelgen.sim.runtime import CompiledModel
    from modelgen.sim.scene import Scene

#: What loading a compiled model imports (numpy, cffi's backend), imported in the
#: functions below, so that a load's generation imports it while its compilers run
#: (:func:`_generate`), not before them; :func:`generate_model` needs none of it.
RUNTIME = ("modelgen.sim.runtime", "cffi", "_cffi_backend")


def generate_model(source, out_dir=None, *, force: bool = False,
                   options: BuildOptions | None = None, progress=None,
                   jacobian: bool | None = None, formulation: str | None = None,
                   linearize: bool | None = None, floating_base: bool | None = None,
                   inertia: str | None = None, min_mass: float | None = None,
                   min_inertia: float | None = None, mimic: str | None = None,
                   kinematics=None,
                   frames=None, max_operations: int | None = None,
                   derivatives: bool | None = None) -> Generated:
    """Generate and compile a model (or reuse the cache); returns the report.

    ``options`` and the shorthand keywords are those of :func:`load`.
    Like :func:`load`, it refuses (:class:`~modelgen.errors.DerivationError`)
    a model whose mass matrix is singular for every configuration, cached or not,
    by the same check (:func:`modelgen.sim.massmatrix.check`), on the library
    opened with ctypes: it imports neither numpy nor cffi.
    ``progress(stage)`` is called as each stage of a build starts.
    """
    options = BuildOptions.of(_options(options), jacobian=jacobian, formulation=formulation,
                              linearize=linearize, floating_base=floating_base,
                              inertia=inertia, min_mass=min_mass, min_inertia=min_inertia,
                              mimic=mimic, kinematics=_kinematics(kinematics, frames),
                              derivatives=derivatives)
    max_operations_of(max_operations)   # before the cache: a hit never builds
    key = _fast_key(source, options, out_dir)
    # the runtime module's place only for the index entry (a spec or Model has none)
    generated, location = _generate(source, out_dir, force, options, progress,
                                    max_operations, load=False, locate=key is not None)
    manifest = generated.manifest
    # the check of a load, through ctypes: no numpy, cffi or runtime module to import
    massmatrix.check(manifest, mass_matrix_function(manifest, generated.build.module_path))
    index.record(key, generated.build, location)
    return generated


def _loaded(manifest: dict, module_path, runtime: tuple | None = None) -> CompiledModel:
    """The compiled model of a build (its manifest and library), checked for a mass
    matrix singular by construction (``runtime``: the runtime module's (name, path),
    else found here).

    The check runs on every load, cached build or not (three evaluations of A:
    microseconds), so a build cache never hides a model that cannot be solved.
    """
    from modelgen.sim.runtime import CompiledModel, check_mass_matrix
    cm = CompiledModel(manifest, module_path, runtime)
    check_mass_matrix(cm)
    return cm


def load(source, out_dir=None, *, force: bool = False, options: BuildOptions | None = None,
         progress=None, jacobian: bool | None = None, formulation: str | None = None,
         linearize: bool | None = None, floating_base: bool | None = None,
         inertia: str | None = None, min_mass: float | None = None,
         min_inertia: float | None = None, mimic: str | None = None, kinematics=None,
         frames=None,
         max_operations: int | None = None,
         derivatives: bool | None = None) -> CompiledModel:
    """Build (on first use) and import a model; returns a :class:`CompiledModel`.

    ``source`` is a YAML path, a URDF (``.urdf``) or MJCF (``.xml``, compiled by
    MuJoCo: :mod:`modelgen.model.mjcf`) file, a :class:`modelgen.model.Model` or a
    ModelSpec.
    Output goes to ``out_dir`` (default: the per-user cache,
    :func:`modelgen.codegen.build.default_output`).  ``options`` (a
    :class:`~modelgen.codegen.options.BuildOptions`) says what to build; the
    keywords below are shorthand for its fields and override them.  With
    ``jacobian=True`` the symbolic Jacobian ``<name>_jacobian`` is generated too
    (for stiff integrators; it costs generation and compile time).
    ``formulation`` (``auto``, ``aba`` or ``crba``) chooses how the rhs computes
    q_ddot (see :data:`modelgen.codegen.options.FORMULATIONS`).
    ``progress(stage)`` is called as each stage of a build starts.
    With ``linearize=True`` the symbolic ``<name>_linearize`` is generated too, for
    :meth:`CompiledModel.linearize` and :meth:`CompiledModel.equilibrium`.
    ``floating_base=True`` (a URDF path) makes the robot's root link a free
    body (a free joint ``root_joint``: position, unit quaternion, 6 speeds);
    ``inertia``, ``min_mass`` and ``min_inertia`` (a URDF path) read bodies that no
    rigid body matches, ``mimic="ignore"`` reads its mimic joints as joints of their
    own (see :func:`modelgen.model.urdf.import_urdf_text`).
    ``kinematics`` (a :class:`~modelgen.codegen.options.KinematicsOptions` or a dict
    of its fields) generates frame poses, velocities, Jacobians and bias
    accelerations, the centre of mass and the centroidal map
    (:mod:`modelgen.sim.kinematics`); ``frames=[...]`` adds frames to
    ``kinematics={"frames": [...]}`` (the two lists joined, each frame once, those of
    ``kinematics`` first), and alone is short for it.
    With ``derivatives=True`` the analytical derivatives ``<name>_derivatives`` and
    ``<name>_inverse_dynamics_derivatives`` are generated too, for
    :meth:`CompiledModel.derivatives` and :meth:`CompiledModel.inverse_dynamics_derivatives`.

    >>> cm = load("models/double_pendulum.yaml", jacobian=True)   # doctest: +SKIP
    >>> cm = load("models/double_pendulum.yaml",                  # doctest: +SKIP
    ...           options=BuildOptions(formulation="crba", jacobian=True))
    >>> cm.rhs(0.0, [0.1, 0.2, 0.0, 0.0])                    # doctest: +SKIP
    """
    options = BuildOptions.of(_options(options), jacobian=jacobian, formulation=formulation,
                              linearize=linearize, floating_base=floating_base,
                              inertia=inertia, min_mass=min_mass, min_inertia=min_inertia,
                              mimic=mimic, kinematics=_kinematics(kinematics, frames),
                              derivatives=derivatives)
    max_operations_of(max_operations)   # before the cache: a hit never builds
    key = _fast_key(source, options, out_dir)
    hit = None if force else index.lookup(key)
    if hit is not None:
        return _loaded(hit.build.manifest, hit.build.module_path, hit.runtime)
    generated, location = _generate(source, out_dir, force, options, progress,
                                    max_operations)
    cm = _loaded(generated.manifest, generated.build.module_path, location)
    index.record(key, generated.build, location)
    return cm


def _options(options):
    """``options`` checked: None or a BuildOptions (a dict would fail deep in the cache)."""
    if options is not None and not isinstance(options, BuildOptions):
        raise ArgumentTypeError(
            f"options must be a BuildOptions or None, got {type(options).__name__}; fix: "
            "options=BuildOptions(jacobian=True, ...), or the keywords (jacobian=True, ...)")
    return options


def _kinematics(kinematics, frames):
    """The ``kinematics`` option of :func:`load`'s keywords (None: not given): the
    frames of ``frames=`` join those of ``kinematics``, after them, each once."""
    if frames is None:
        return kinematics
    if isinstance(frames, str):
        frames = [frames]
    if not (isinstance(frames, (list, tuple)) and all(isinstance(f, str) for f in frames)):
        raise ArgumentTypeError(f"frames must be a frame name or a list of frame names, got "
                                f"{frames!r}; fix: frames=['tool0', ...]")
    given = KinematicsOptions.parse(kinematics)
    joined = tuple(dict.fromkeys(given.frames + tuple(frames)))   # each once, in order
    return KinematicsOptions.of(replace(given, frames=joined))


def _fast_key(source, options: BuildOptions, out_dir) -> str | None:
    """The fast index key of a model file (None for a spec or a Model: only a file
    read here is known to give the spec its bytes say)."""
    if not isinstance(source, (str, Path)):
        return None
    return index.fast_key([source], options, out_dir)


def _generate(source, out_dir, force: bool, options: BuildOptions, progress,
              max_operations: int | None = None, *, load: bool = True,
              locate: bool = True) -> tuple:
    """The full path: read the model, then generate (or find by the build key).
    Returns the :class:`Generated` and the runtime module's (name, path), or None
    without ``locate``.  With ``load``, what loading the library imports
    (:data:`RUNTIME`) is imported while the compilers run."""
    # imported here, not at the top: the reader and the symbolic pipeline (about a
    # second of imports) are needed only when the fast index has no build
    from modelgen.codegen.pipeline import generate, runtime
    from modelgen.model import as_spec
    found = []

    def while_compiling():
        # what loading the library needs, while this process only waits for the
        # compilers: the loader's imports and the runtime module's place (which
        # builds the runtime module on first use, beside them)
        for name in RUNTIME if load else ():
            importlib.import_module(name)
        if locate:
            found.append(runtime())
    generated = generate(as_spec(source, **options.reading()), out_dir,
                         force=force, options=options, progress=progress,
                         max_operations=max_operations,
                         while_compiling=while_compiling if load or locate else None)
    if not locate:
        return generated, None
    return generated, found[0] if found else runtime()


def load_scene(path, out_dir=None, *, force: bool = False, progress=None,
               options: BuildOptions | None = None, linearize: bool | None = None,
               max_operations: int | None = None) -> Scene:
    """Load a scene file and build its reduced model; returns a :class:`Scene`.

    Only the effects and outputs the scene selects are generated.  Output goes
    to ``out_dir`` (default: the per-user cache).  ``linearize=True`` adds the
    symbolic linearization, outputs included (``scene.model.linearize(...)``).
    ``options`` (:class:`~modelgen.codegen.options.BuildOptions`) is merged with
    what the scene asks for (its outputs; the Jacobian for stiff effects).

    >>> res = load_scene("models/scenes/dp_damped.yaml").run()   # doctest: +SKIP
    """
    # imported here: a plain model's load does not need the scene module
    from modelgen.sim.scene import Scene, read_card
    options = BuildOptions.of(_options(options), linearize=linearize)
    max_operations_of(max_operations)   # before the cache: a hit never builds
    card, spec = read_card(path, out_dir, force=force)
    return Scene(card, out_dir, force=force, progress=progress, options=options,
                 files=(card.source, card.model_source), max_operations=max_operations,
                 scene_spec=spec)
