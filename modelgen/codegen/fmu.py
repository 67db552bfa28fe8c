"""FMI 2.0 export: a model or a scene -> one FMU for Model Exchange and Co-Simulation.

Input: a model (YAML path, :class:`~modelgen.model.Model`, ModelSpec) or a
scene (YAML path or SceneSpec).  Output: a ``.fmu`` archive holding

- ``modelDescription.xml``: the state ``q1.., q1_dot..`` and its derivatives
  ``der(q1)..`` (``derivative=`` attributes), the parameters as tunable
  parameters with their defaults as start values, the inputs as continuous
  inputs, a scene's outputs as outputs (their columns, e.g. ``elbow.x``), the
  ``ModelStructure``, and the Co-Simulation integrator (method and
  tolerances, fixed at export) in ``description`` and a vendor annotation;
- ``sources/``: the model's C (``<name>.c``/``.h`` from :func:`generate`),
  modelgen's integrators (``mg_integrate.c``/``.h`` and the ``mg_integrate/``
  files that ``mg_integrate.c`` includes), the FMI wrapper
  (``<name>_fmi2.c``, rendered from ``templates/fmu/fmi2.c.j2``) and the FMI
  2.0 headers with their licence, so an importer can rebuild it anywhere;
- ``binaries/<platform>/<name>.<so|dylib>``: compiled here.

The model's equations come from the ordinary pipeline (and its cache); the
FMU's C is the model's own, nothing is re-derived for the export.  Units:
the model format has none, so the variables carry none.

>>> fmu = build_fmu("models/double_pendulum.yaml", "dp.fmu")     # doctest: +SKIP
>>> fmu.path, fmu.settings.method                                 # doctest: +SKIP
(PosixPath('dp.fmu'), 'dop853')
"""
from __future__ import annotations

import hashlib
import json
import math
import os
import platform
import struct
import tempfile
import time
import uuid
import zipfile
from dataclasses import dataclass, replace
from pathlib import Path
from xml.etree import ElementTree as ET

from modelgen.codegen import capi
from modelgen.codegen.build import (compile_flags, compiler, integrator_object, link_command,
                                    run_commands, write_sources)
from modelgen.codegen.emit import INTEGRATOR_HEADER, integrator_files, render
from modelgen.codegen.options import BuildOptions
from modelgen.codegen.pipeline import generate, model_hash
from modelgen.errors import BuildError, ModelError, ModelgenError
from modelgen.model import as_spec, is_scene_file, load_scene
from modelgen.model.spec import ModelSpec, SceneSpec
from modelgen.version import __version__

#: The FMI 2.0 headers vendored from the standard (modelica/fmi-standard, tag v2.0.5).
FMI2_HEADERS = ("fmi2Functions.h", "fmi2FunctionTypes.h", "fmi2TypesPlatform.h")
#: Their licence (BSD 2-clause for the headers), shipped beside them in every FMU.
FMI2_LICENSE = "LICENSE.txt"
#: Attempted integrator steps per Co-Simulation step before fmi2DoStep fails.
MAX_STEPS = 1_000_000
#: The logger categories of the FMU (modelDescription's LogCategories).
LOG_CATEGORIES = (
    ("logStatusError", "errors: a misused call or a failed computation (always reported)"),
    ("logStatusDiscard", "a Co-Simulation step that stopped short, or a status the FMU "
                         "cannot give (always reported)"),
    ("logDebug", "what the FMU does: instantiation, initialization, each Co-Simulation step"),
)
#: Default Co-Simulation integrator of a model (a scene brings its own).
DEFAULT_METHOD, DEFAULT_RTOL, DEFAULT_ATOL = "dop853", 1e-8, 1e-10


def fmi2_dir() -> Path:
    """Where the vendored FMI 2.0 headers and their licence live."""
    return Path(__file__).resolve().parent / "fmi2"


@dataclass(frozen=True)
class CoSimulationSettings:
    """How ``fmi2DoStep`` integrates: a method of :data:`modelgen.codegen.capi.METHODS`,
    its tolerances (adaptive methods) or step (fixed-step ones)."""
    method: str
    rtol: float
    atol: float
    step: float | None
    max_steps: int = MAX_STEPS

    def describe(self) -> str:
        """One line for the model description, e.g. ``dop853, rtol 1e-08, atol 1e-10``."""
        if capi.METHODS[self.method].adaptive:
            return f"{self.method}, rtol {self.rtol!r}, atol {self.atol!r}"
        return f"{self.method}, fixed steps of {self.step!r} s"


@dataclass(frozen=True)
class FmuVariable:
    """One ScalarVariable of the FMU (all are Real; the value reference is its index)."""
    name: str
    value_reference: int
    causality: str          # local | parameter | input | output
    variability: str        # continuous | tunable
    initial: str | None     # exact | calculated | None (inputs)
    start: float | None
    description: str
    derivative_of: int | None = None    # value reference of the state it is der() of
    unit: str = ""                      # from the model's units: (a speed: its coordinate's/s)
    #: value reference of the state this derivative equals (a simple coordinate's
    #: speed), else None (calculated from the whole state)
    equals: int | None = None


@dataclass(frozen=True)
class Fmu:
    """What :func:`build_fmu` wrote."""
    path: Path
    model_identifier: str
    guid: str
    platform: str
    settings: CoSimulationSettings
    variables: tuple        # FmuVariable, in value-reference order
    seconds: float

    def names(self, causality: str) -> list:
        """Names of the variables of one causality, in value-reference order."""
        return [v.name for v in self.variables if v.causality == causality]


@dataclass(frozen=True)
class _Source:
    """A model or scene resolved to what the export needs."""
    spec: ModelSpec
    outputs: tuple
    initial: tuple
    input_starts: tuple
    experiment: tuple | None     # (start, stop, sample) of a scene
    defaults: tuple              # (method, rtol, atol, step)
    jacobian: bool


def _resolve(source) -> _Source:
    """A model or scene source as a :class:`_Source`."""
    if isinstance(source, (str, os.PathLike)) and is_scene_file(source):
        source = load_scene(source)
    if isinstance(source, SceneSpec):
        s = source
        starts = tuple(_signal_start(sig, s.t_start) for sig in s.inputs) \
            if s.inputs else (0.0,) * len(s.model.inputs)
        by_name = {sig.name: v for sig, v in zip(s.inputs, starts)}
        return _Source(s.model, tuple(s.outputs), tuple(float(v) for v in s.initial),
                       tuple(by_name.get(u, 0.0) for u in s.model.inputs),
                       (s.t_start, s.t_end, s.sample_dt), (s.method, s.rtol, s.atol, s.step),
                       # the rule of modelgen.sim.scene.Scene, so both share one build
                       bool(s.stiff_effects) and s.model.n <= 12)
    spec = as_spec(source)
    return _Source(spec, (), _rest(spec), (0.0,) * len(spec.inputs), None,
                   (DEFAULT_METHOD, DEFAULT_RTOL, DEFAULT_ATOL, None), False)


def _rest(spec: ModelSpec) -> tuple:
    """A model's start values: every coordinate and speed zero, but each ball or free
    joint's quaternion the identity (w = 1; zero is no rotation)."""
    x = dict.fromkeys((*spec.coordinates, *spec.speeds), 0.0)
    x.update((j.quaternion[0], 1.0) for j in spec.joints)
    return tuple(x.values())


def _signal_start(signal, t0: float) -> float:
    """An input signal's value at the scene's start (its constant, or its samples there)."""
    if signal.constant is not None:
        return float(signal.constant)
    times, values = signal.times, signal.values
    if t0 <= times[0]:
        return float(values[0])
    for k in range(len(times) - 1):
        if times[k] <= t0 < times[k + 1]:
            if signal.interpolation == "hold":
                return float(values[k])
            w = (t0 - times[k]) / (times[k + 1] - times[k])
            return float(values[k] + w * (values[k + 1] - values[k]))
    return float(values[-1])


def _settings(method, rtol, atol, step, defaults) -> CoSimulationSettings:
    """The Co-Simulation integrator from the arguments over the source's defaults, checked."""
    d_method, d_rtol, d_atol, d_step = defaults
    name = method if method is not None else d_method
    name = capi.ALIASES.get(name, name)
    if name not in capi.METHODS:
        raise ModelgenError(f"unknown integration method {name!r}; fix: use one of "
                            + ", ".join(capi.METHODS))
    values = {"rtol": d_rtol if rtol is None else rtol, "atol": d_atol if atol is None else atol}
    for key, value in values.items():
        if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
            raise ModelgenError(f"{key} must be a positive number, got {value!r}")
    if values["rtol"] >= 1:
        raise ModelgenError(f"rtol must be below 1, got {values['rtol']!r}")
    adaptive = capi.METHODS[name].adaptive
    if step is not None and adaptive:
        raise ModelgenError(f"method {name} adapts its steps to rtol and atol; fix: drop the "
                            f"step, or choose a fixed-step method (rk4, midpoint, gauss4)")
    step = step if step is not None else d_step
    if step is None and not adaptive:
        raise ModelgenError(f"method {name} takes fixed steps; fix: give the step "
                            f"(step=..., --step) or choose an adaptive method (dopri5, dop853, "
                            f"rodas)")
    if step is not None and not (math.isfinite(step) and step > 0):
        raise ModelgenError(f"step must be a positive number of seconds, got {step!r}")
    return CoSimulationSettings(name, float(values["rtol"]), float(values["atol"]),
                                None if adaptive else float(step))


def _variables(src: _Source, output_columns) -> tuple:
    """Every ScalarVariable, in value-reference order (states, derivatives, parameters,
    inputs, outputs), with unique names checked."""
    spec = src.spec
    coordinates, speeds = list(spec.coordinates), list(spec.speeds)
    states, nq, simple = coordinates + speeds, len(coordinates), len(spec.simple_coordinates)
    units = spec.name_units
    state_units = [units.get(name, "") for name in states]
    joint_of = {n: j.name for j in spec.joints for n in (*j.coordinates, *j.speeds)}
    out = []
    for i, name in enumerate(states):
        what = (f"generalized coordinate {i + 1}" if i < simple else
                f"coordinate {name} of joint {joint_of[name]}" if i < nq else
                f"speed, the time derivative of {coordinates[i - nq]}" if i < nq + simple else
                f"speed {name} of joint {joint_of[name]}")
        out.append(FmuVariable(name, len(out), "local", "continuous", "exact",
                               float(src.initial[i]), what, unit=state_units[i]))
    for i, name in enumerate(states):
        what = (f"= {speeds[i]}" if i < simple else
                f"rate of {name}, from the speeds of joint {joint_of[name]}" if i < nq else
                f"acceleration of {coordinates[i - nq]}" if i < nq + simple else
                f"rate of {name}")
        unit = (state_units[nq + i] if i < simple else "" if i < nq else
                state_units[i - nq] and f"{state_units[i - nq]}/s2" if i < nq + simple else "")
        out.append(FmuVariable(f"der({name})", len(out), "local", "continuous", "calculated",
                               None, what, derivative_of=i, unit=unit,
                               equals=nq + i if i < simple else None))
    for name, value in spec.parameters:
        out.append(FmuVariable(name, len(out), "parameter", "tunable", "exact", float(value),
                               "parameter", unit=units.get(name, "")))
    for name, value in zip(spec.inputs, src.input_starts):
        out.append(FmuVariable(name, len(out), "input", "continuous", None, float(value),
                               "input", unit=units.get(name, "")))
    kinds = {o.name: o for o in src.outputs}
    for column in output_columns:
        head = column.split(".")[0].split("[")[0]
        o = kinds.get(head)
        what = f"{o.kind} output {o.name}" if o else "output"
        out.append(FmuVariable(column, len(out), "output", "continuous", "calculated", None,
                               what))
    seen = {}
    for v in out:
        if v.name in seen:
            raise ModelError(f"two FMU variables would be named {v.name!r} (a "
                             f"{seen[v.name]} and a {v.causality})", file=spec.source,
                             fix="rename one of them: FMI names must be unique")
        seen[v.name] = v.causality
    return tuple(out)


def _guid(hash_of_model: str, settings: CoSimulationSettings, variables) -> str:
    h = hashlib.sha256(json.dumps([hash_of_model, __version__, repr(settings),
                                   [repr(v) for v in variables]]).encode()).hexdigest()
    return "{" + str(uuid.UUID(hex=h[:32])) + "}"


def fmi_platform() -> tuple:
    """(FMI 2.0 platform folder, shared library suffix) of this machine."""
    system, bits = platform.system(), 8 * struct.calcsize("P")
    if system == "Linux":
        return f"linux{bits}", ".so"
    if system == "Darwin":
        return "darwin64", ".dylib"
    if system == "Windows":
        return f"win{bits}", ".dll"
    raise BuildError(f"FMI 2.0 names no binary folder for {system}",
                     fix="build the FMU on Linux, macOS or Windows, or compile its sources/ "
                         "for this platform")


# -- the model description ---------------------------------------------------------

def _number(value: float) -> str:
    return repr(float(value))


def model_description(name: str, description: str, guid: str, variables, settings,
                      sources, experiment=None, completed_step_needed=False) -> str:
    """The text of ``modelDescription.xml`` (FMI 2.0, naming convention flat).
    ``completed_step_needed``: Model Exchange must call fmi2CompletedIntegratorStep
    (a constrained model, or one with quaternions, checks there whether its state
    drifted off the constraints or off unit length)."""
    root = ET.Element("fmiModelDescription", {
        "fmiVersion": "2.0", "modelName": name, "guid": guid,
        "description": description,
        "generationTool": f"modelgen {__version__}",
        "variableNamingConvention": "flat", "numberOfEventIndicators": "0"})
    common = {"modelIdentifier": name, "canNotUseMemoryManagementFunctions": "false",
              "canGetAndSetFMUstate": "false", "canSerializeFMUstate": "false",
              "providesDirectionalDerivative": "false"}
    me = ET.SubElement(root, "ModelExchange", dict(
        common, completedIntegratorStepNotNeeded="false" if completed_step_needed else "true"))
    cs = ET.SubElement(root, "CoSimulation", dict(
        common, canHandleVariableCommunicationStepSize="true", canInterpolateInputs="false",
        maxOutputDerivativeOrder="0", canRunAsynchronuously="false"))
    for kind in (me, cs):
        files = ET.SubElement(kind, "SourceFiles")
        for source in sources:
            ET.SubElement(files, "File", {"name": source})
    unit_names = sorted({v.unit for v in variables if v.unit})
    if unit_names:
        definitions = ET.SubElement(root, "UnitDefinitions")
        for unit in unit_names:
            ET.SubElement(definitions, "Unit", {"name": unit})
    categories = ET.SubElement(root, "LogCategories")
    for category, text in LOG_CATEGORIES:
        ET.SubElement(categories, "Category", {"name": category, "description": text})
    default = {"tolerance": _number(settings.rtol)}
    if experiment is not None:
        start, stop, sample = experiment
        default = {"startTime": _number(start), "stopTime": _number(stop),
                   "tolerance": _number(settings.rtol), "stepSize": _number(sample)}
    ET.SubElement(root, "DefaultExperiment", default)
    tool = ET.SubElement(ET.SubElement(root, "VendorAnnotations"), "Tool", {"name": "modelgen"})
    annotation = {"method": settings.method, "maxSteps": str(settings.max_steps)}
    if settings.step is None:
        annotation.update(rtol=_number(settings.rtol), atol=_number(settings.atol))
    else:
        annotation.update(step=_number(settings.step))
    ET.SubElement(tool, "CoSimulationIntegrator", annotation)

    model_variables = ET.SubElement(root, "ModelVariables")
    for v in variables:
        attributes = {"name": v.name, "valueReference": str(v.value_reference),
                      "description": v.description, "causality": v.causality,
                      "variability": v.variability}
        if v.initial:
            attributes["initial"] = v.initial
        scalar = ET.SubElement(model_variables, "ScalarVariable", attributes)
        real = {}
        if v.derivative_of is not None:
            real["derivative"] = str(v.derivative_of + 1)       # 1-based index
        if v.start is not None:
            real["start"] = _number(v.start)
        if v.unit:
            real["unit"] = v.unit
        ET.SubElement(scalar, "Real", real)

    index = {v.value_reference: v.value_reference + 1 for v in variables}
    structure = ET.SubElement(root, "ModelStructure")
    outputs = [v for v in variables if v.causality == "output"]
    derivatives = [v for v in variables if v.derivative_of is not None]
    if outputs:
        element = ET.SubElement(structure, "Outputs")
        for v in outputs:      # on the state and the inputs (no dependencies: all of them)
            ET.SubElement(element, "Unknown", {"index": str(index[v.value_reference])})
    element = ET.SubElement(structure, "Derivatives")
    for v in derivatives:
        attributes = {"index": str(index[v.value_reference])}
        if v.equals is not None:       # der(q_i) is q_i_dot, and nothing else
            attributes.update(dependencies=str(index[v.equals]), dependenciesKind="constant")
        ET.SubElement(element, "Unknown", attributes)
    element = ET.SubElement(structure, "InitialUnknowns")
    for v in sorted(outputs + derivatives, key=lambda v: v.value_reference):
        ET.SubElement(element, "Unknown", {"index": str(index[v.value_reference])})
    ET.indent(root, "  ")
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") \
        + "\n"


# -- the C --------------------------------------------------------------------------

def _c_string(text: str) -> str:
    """A C string literal of ``text`` (names are ASCII identifiers and column labels)."""
    return json.dumps(text, ensure_ascii=True)


def wrapper_source(name: str, hash16: str, guid: str, variables, settings,
                   initial, input_starts, n_outputs: int, constraints=None,
                   quaternions=None) -> str:
    """``<name>_fmi2.c``: the FMI 2.0 functions over the model's C (``fmu/fmi2.c.j2``).
    ``constraints``: the manifest's entry of a constrained model (its equations
    ``m``, the position ones ``holonomic``), else None; ``quaternions``: the
    manifest's state indices (w, x, y, z) of each ball or free joint's quaternion."""
    method = capi.METHODS[settings.method]
    codes = [s.code for s in capi.STATUSES]
    by_code = {s.code: s.name for s in capi.STATUSES}
    context = {
        "template": "fmu/fmi2.c.j2", "version": __version__, "model_hash": hash16,
        "name": name, "NAME": name.upper(), "guid": guid,
        "variable_names": [_c_string(v.name) for v in variables],
        "x_start": [_number(v) for v in initial],
        "u_start": [_number(v) for v in input_starts] or ["0.0"],
        "statuses": [_c_string(by_code.get(k, "UNKNOWN"))
                     for k in range(min(codes), max(codes) + 1)],
        "status_min": min(codes),
        "method": settings.method, "method_define": f"{capi.PREFIX}_METHOD_{method.name.upper()}",
        "adaptive": int(method.adaptive),
        "rtol": _number(settings.rtol), "atol": _number(settings.atol),
        "fixed_step": _number(settings.step or 0.0), "max_steps": str(settings.max_steps),
        "ny": n_outputs,
        "constraints": ({"m": int(constraints["m"]), "mh": int(constraints["holonomic"]),
                         "dep": [int(k) for k in constraints["dependent_speeds"]]}
                        if constraints else None),
        "quaternions": [[int(k) for k in quat] for quat in quaternions or ()],
    }
    return render("fmu/fmi2.c.j2", context)


def _model_sources(spec: ModelSpec, outputs, jacobian: bool, out_dir) -> tuple:
    """(``<name>.c``, ``<name>.h``, mg_integrate sources, manifest, hash16) from the
    pipeline's build, regenerated in a private directory when the build directory's
    C is another variant's (one directory keeps several builds of one name)."""
    options = BuildOptions(outputs=outputs, jacobian=jacobian)
    generated = generate(spec, out_dir, options=options)
    manifest = generated.manifest
    hash16 = model_hash(spec, replace(options, formulation=manifest["formulation"]))[:16]

    def read(directory: Path):
        texts = {f: (directory / f).read_text() for f in
                 (f"{spec.name}.c", f"{spec.name}.h", INTEGRATOR_HEADER, *integrator_files())}
        ok = all(f"Model hash: {hash16}" in texts[f] for f in (f"{spec.name}.c",
                                                                f"{spec.name}.h"))
        return texts, ok
    try:
        texts, ok = read(generated.build.directory)
    except OSError:
        texts, ok = {}, False
    if not ok:
        with tempfile.TemporaryDirectory(prefix="modelgen-fmu-") as tmp:
            again = generate(spec, Path(tmp), options=options, force=True)
            manifest = again.manifest
            texts, ok = read(Path(tmp))
    return texts, manifest, hash16


def compile_library(directory: Path, name: str, sources: list, statements: int,
                    suffix: str, objects=()) -> Path:
    """Compile the C files ``sources`` in ``directory`` (``-Werror``) and link them with
    ``objects`` into ``<name><suffix>``.  Only the fmi2 functions are exported:
    the sources compile with ``-fvisibility=hidden`` and, on Linux, a version script
    hides the objects' symbols too, so two FMUs never interpose on each other."""
    cc = compiler()
    commands = [[*cc, *compile_flags(statements, 0), "-Werror", "-fvisibility=hidden", "-I.",
                 "-c", source, "-o", source[:-2] + ".o"] for source in sources]
    run_commands(commands, directory, "C compiler failed building the FMU")
    library = f"{name}{suffix}"
    link = link_command([*(s[:-2] + ".o" for s in sources), *map(str, objects)], library)
    if platform.system() == "Linux":
        (directory / "exports.map").write_text("{\n  global: fmi2*;\n  local: *;\n};\n")
        link.insert(-3, "-Wl,--version-script=exports.map")
    run_commands([link], directory, "the FMU's library failed to link")
    return directory / library


def _write_archive(path: Path, files: dict) -> None:
    """Write ``files`` (archive name -> bytes) as a zip, atomically, with fixed timestamps."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}-", dir=path.parent)
    os.close(fd)
    try:
        with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as archive:
            for name in sorted(files):
                info = zipfile.ZipInfo(name, date_time=(1980, 1, 1, 0, 0, 0))
                info.compress_type = zipfile.ZIP_DEFLATED
                info.external_attr = 0o644 << 16
                archive.writestr(info, files[name])
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def build_fmu(source, out_path, *, method: str | None = None, rtol: float | None = None,
              atol: float | None = None, step: float | None = None, out_dir=None) -> Fmu:
    """Export a model or scene as an FMI 2.0 FMU (Model Exchange and Co-Simulation).

    ``source``: a model or scene YAML path, a :class:`~modelgen.model.Model`, a
    ModelSpec or a SceneSpec.  ``out_path``: the ``.fmu`` file, or a directory to
    write ``<name>.fmu`` into.  ``method``, ``rtol``, ``atol`` and ``step`` choose
    the integrator of Co-Simulation's ``fmi2DoStep`` (default: a scene's own,
    else dop853 at rtol 1e-8, atol 1e-10); they are recorded in the model
    description.  ``out_dir``: where the model is generated (default: the
    per-user cache, shared with :func:`modelgen.load`).  Returns an :class:`Fmu`.

    >>> fmu = build_fmu("models/cart_pole.yaml", "out/cart_pole.fmu")   # doctest: +SKIP
    >>> fmu.names("input")                                               # doctest: +SKIP
    ['F']
    """
    start = time.perf_counter()
    src = _resolve(source)
    spec = src.spec
    settings = _settings(method, rtol, atol, step, src.defaults)
    jacobian = src.jacobian or capi.METHODS[settings.method].implicit
    texts, manifest, hash16 = _model_sources(spec, src.outputs, jacobian, out_dir)
    columns = [c for o in manifest["outputs"] for c in o["columns"]]
    variables = _variables(src, columns)
    guid = _guid(hash16, settings, variables)
    folder, suffix = fmi_platform()
    wrapper = f"{spec.name}_fmi2.c"
    texts[wrapper] = wrapper_source(spec.name, hash16, guid, variables, settings, src.initial,
                                    src.input_starts, len(columns),
                                    manifest.get("constraints"), manifest.get("quaternions"))
    for header in FMI2_HEADERS + (FMI2_LICENSE,):
        texts[header] = (fmi2_dir() / header).read_text()
    c_files = [f"{spec.name}.c", "mg_integrate.c", wrapper]
    integrators, _ = integrator_object({f: texts[f] for f in (INTEGRATOR_HEADER,
                                                               *integrator_files())})
    description = (f"{spec.description + ' ' if spec.description else ''}(exported by modelgen "
                   f"{__version__}; Co-Simulation integrates with mg_integrate: "
                   f"{settings.describe()})")
    xml = model_description(spec.name, description, guid, variables, settings, c_files,
                            src.experiment,
                            bool(manifest.get("constraints") or manifest.get("quaternions")))
    statements = max(o["statements"] for o in manifest["ops"].values())
    with tempfile.TemporaryDirectory(prefix="modelgen-fmu-") as tmp:
        tmp = Path(tmp)
        write_sources(tmp, texts)
        library = compile_library(tmp, spec.name, [f"{spec.name}.c", wrapper], statements,
                                  suffix, [integrators])
        files = {"modelDescription.xml": xml.encode(),
                 f"binaries/{folder}/{library.name}": library.read_bytes()}
        for fname, text in texts.items():
            target = "fmi2-headers-LICENSE.txt" if fname == FMI2_LICENSE else fname
            files[f"sources/{target}"] = text.encode()
        out_path = Path(out_path)
        if out_path.suffix.lower() != ".fmu":
            out_path = out_path / f"{spec.name}.fmu"
        _write_archive(out_path, files)
    return Fmu(out_path, spec.name, guid, folder, settings, variables,
               time.perf_counter() - start)
