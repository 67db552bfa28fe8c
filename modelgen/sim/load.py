"""From a model source to a loaded :class:`CompiledModel` or :class:`Scene`: the front door.

These are the functions ``modelgen.load``, ``modelgen.load_scene`` and
``modelgen.generate_model`` re-export.
"""
from __future__ import annotations

from modelgen.codegen.pipeline import Generated, generate
from modelgen.model import as_spec
from modelgen.model.scene import load_scene as load_scene_spec
from modelgen.sim.runtime import CompiledModel, check_mass_matrix
from modelgen.sim.scene import Scene


def generate_model(source, out_dir=None, *, force: bool = False,
                   jacobian: bool = False, formulation: str = "auto",
                   progress=None, linearize: bool = False) -> Generated:
    """Generate and compile a model (or reuse the cache); returns the report.

    Like :func:`load`, it refuses (:class:`~modelgen.errors.DerivationError`)
    a model whose mass matrix is singular for every configuration, cached or not.
    ``progress(stage)`` is called as each stage of a build starts.
    """
    generated = generate(as_spec(source), out_dir, force=force, jacobian=jacobian,
                         formulation=formulation, progress=progress, linearize=linearize)
    _loaded(generated)
    return generated


def _loaded(generated: Generated) -> CompiledModel:
    """The compiled model of a build, checked for a mass matrix singular by construction.

    The check runs on every load, cached build or not (three evaluations of A:
    microseconds), so a build cache never hides a model that cannot be solved.
    """
    cm = CompiledModel(generated.manifest, generated.build.module_path)
    check_mass_matrix(cm)
    return cm


def load(source, out_dir=None, *, force: bool = False, jacobian: bool = False,
         formulation: str = "auto", progress=None, linearize: bool = False,
         floating_base: bool = False) -> CompiledModel:
    """Build (on first use) and import a model; returns a :class:`CompiledModel`.

    ``source`` is a YAML path, a URDF (``.urdf``) or MJCF (``.xml``, compiled by
    MuJoCo: :mod:`modelgen.model.mjcf`) file, a :class:`modelgen.model.Model` or a
    ModelSpec.
    Output goes to ``out_dir`` (default: the per-user cache,
    :func:`modelgen.codegen.pipeline.default_output`).  With
    ``jacobian=True`` the symbolic Jacobian ``<name>_jacobian`` is generated too
    (for stiff integrators; it costs generation and compile time).
    ``formulation`` (``auto``, ``aba`` or ``crba``) chooses how the rhs computes
    q_ddot (see :data:`modelgen.codegen.pipeline.FORMULATIONS`).
    ``progress(stage)`` is called as each stage of a build starts.
    With ``linearize=True`` the symbolic ``<name>_linearize`` is generated too, for
    :meth:`CompiledModel.linearize` and :meth:`CompiledModel.equilibrium`.
    ``floating_base=True`` (a URDF path) makes the robot's root link a free
    body (a free joint ``root_joint``: position, unit quaternion, 6 speeds).

    >>> cm = load("models/double_pendulum.yaml")             # doctest: +SKIP
    >>> cm.rhs(0.0, [0.1, 0.2, 0.0, 0.0])                    # doctest: +SKIP
    """
    return _loaded(generate(as_spec(source, floating_base=floating_base), out_dir, force=force, jacobian=jacobian,
                            formulation=formulation, progress=progress,
                            linearize=linearize))


def load_scene(path, out_dir=None, *, force: bool = False, progress=None,
               linearize: bool = False) -> Scene:
    """Load a scene file and build its reduced model; returns a :class:`Scene`.

    Only the effects and outputs the scene selects are generated.  Output goes
    to ``out_dir`` (default: the per-user cache).  ``linearize=True`` adds the
    symbolic linearization, outputs included (``scene.model.linearize(...)``).

    >>> res = load_scene("models/scenes/dp_damped.yaml").run()   # doctest: +SKIP
    """
    return Scene(load_scene_spec(path), out_dir, force=force, progress=progress,
                 linearize=linearize)
