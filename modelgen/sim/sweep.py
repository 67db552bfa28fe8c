"""Sweeps: parameter studies and Monte Carlo runs, in-process or on a Dask cluster.

:func:`sweep` runs one model over many parameter sets and initial states: an
``xarray.Dataset``.  A run that fails keeps its trajectory up to the failure
(NaN after it), its status and message; it never fails the sweep.  Each chunk
of runs is one :meth:`CompiledModel.simulate_batch` call, in-process or on a
Dask worker, which loads the scattered :class:`ModelPayload` once per process
(:func:`worker_model`: the shared build, else rebuilt from the shipped sources).
Only a rebuild imports the code generator (sympy: 0.6 s and 40 MB per worker
process), so this module imports none of it.  Needs the ``sweep`` extra.
"""
from __future__ import annotations

import math
import hashlib
import os
import threading
import time
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from modelgen.codegen.build import build_module, cache_lookup, default_output
from modelgen.errors import (ArgumentTypeError, ArgumentValueError, ModelgenError,
                             SimulationError)
from modelgen.model import as_spec, is_scene_file
from modelgen.sim.arguments import whole_number
from modelgen.sim.integrate import (DEFAULT_MAX_STEPS, INTERRUPTED, STATUS_BY_NAME,
                                    method_of, step_budget)
from modelgen.sim.load import load, load_scene
from modelgen.sim.runtime import CompiledModel, unpickled
from modelgen.sim.scene import Scene
from modelgen.sim.sweep_results import REDUCTIONS, plot_scalar, scalar, summary
from modelgen.version import __version__

__all__ = ["grid", "sweep", "Study", "ModelPayload", "payload_of", "worker_model",
           "builds_in_this_process", "run_chunk", "summary", "scalar", "plot_scalar",
           "require", "check_client", "REDUCTIONS"]

#: what ``pip install`` line provides the optional dependencies
EXTRA = "pip install 'modelgen[sweep]'"
#: chunks per worker thread when no chunk size is given (load balance against overhead)
CHUNKS_PER_WORKER = 4
#: chunks of an in-process sweep: progress is reported between two C calls
PROGRESS_CHUNKS = 50
#: per-run counters of the integrator kept in the dataset
COUNTERS = ("nfev", "naccept", "nreject")


def require(*modules: str):
    """Import the optional modules a sweep needs; a :class:`ModelgenError` naming the
    ``sweep`` extra when one is missing.  Returns the modules."""
    import importlib
    out = []
    for name in modules:
        try:
            out.append(importlib.import_module(name))
        except ImportError as exc:
            raise ModelgenError(f"sweeps need {name.split('.')[0]} ({exc}); fix: {EXTRA}") \
                from None
    return out[0] if len(out) == 1 else out


def grid(**axes) -> dict:
    """The Cartesian product of named 1-D axes as flat arrays of equal length (the
    last axis varies fastest).

    >>> g = grid(m2=[1.0, 2.0], q1=[0.1, 0.2, 0.3])
    >>> g["m2"].tolist(), g["q1"].tolist()
    ([1.0, 1.0, 1.0, 2.0, 2.0, 2.0], [0.1, 0.2, 0.3, 0.1, 0.2, 0.3])
    """
    arrays = {}
    for name, values in axes.items():
        arrays[name] = _row(values, f"grid axis {name!r}", "a non-empty 1-D array",
                            f"give the axis's values, e.g. {name}=np.linspace(0.5, 2.0, 16)")
    if not arrays:
        return {}
    mesh = np.meshgrid(*arrays.values(), indexing="ij")
    return {name: m.ravel().copy() for name, m in zip(arrays, mesh)}


def _real_array(values, what: str, example: str = "[0.5, 1.0, 2.0]") -> np.ndarray:
    """``values`` as an array of floats (at least 1-D): numbers or arrays of them, never a
    string or a complex number, which numpy would refuse (or cut to its real part)
    with a message naming neither the argument nor the fix."""
    try:
        a = np.asarray(values)
        if a.dtype.kind not in "biufO":     # O: numbers of other types, converted below
            raise TypeError
        return np.atleast_1d(a.astype(float))
    except (TypeError, ValueError, OverflowError):
        raise ArgumentTypeError(f"{what} must be a real number or an array of them, got "
                                f"{values!r:.80}; fix: give numbers, e.g. {example}") \
            from None


def _row(values, what: str, expected: str, fix: str) -> np.ndarray:
    """``values`` as a non-empty 1-D float array (:func:`_real_array`), else an
    ArgumentValueError saying it must be ``expected``."""
    a = _real_array(values, what)
    if a.ndim != 1 or a.size == 0:
        raise ArgumentValueError(f"{what} must be {expected}, got shape {a.shape}; fix: {fix}")
    return a


# -- the model, on the driver and on the workers --------------------------------------

def load_model(source, build_dir=None):
    """``(CompiledModel, defaults)`` of a sweep's source: a scene file or
    :class:`Scene` (defaults: its times, method, tolerances, step, inputs and initial
    state), a model file or spec, or a :class:`CompiledModel` (no defaults)."""
    if isinstance(source, CompiledModel):
        return source, {}
    if isinstance(source, (str, os.PathLike)) and is_scene_file(source):
        source = load_scene(source, build_dir)
    if isinstance(source, Scene):
        s = source.spec
        fixed = not method_of(s.method).adaptive
        return source.model, {"t_eval": source.times(), "t_span": (s.t_start, s.t_end),
                              "method": s.method, "rtol": s.rtol, "atol": s.atol,
                              "step": s.step if fixed else None, "u": source.input_signal(),
                              "x0": source.initial_state(), "scene": s.name}
    return load(as_spec(source), build_dir), {}


@dataclass(frozen=True)
class ModelPayload:
    """What a worker needs to load a compiled model: manifest, module path, the generated
    sources to rebuild it where that path does not exist, runtime module (name, path)."""
    manifest: dict
    module_path: str
    sources: dict | None = field(repr=False)   # None: they could not be verified
    runtime: tuple | None = None

    @property
    def build_hash(self) -> str:
        return self.manifest["build_hash"]


def payload_of(cm: CompiledModel) -> ModelPayload:
    """The :class:`ModelPayload` of a loaded model (its sources read from its build
    directory, where the pipeline wrote them next to the module)."""
    directory, name = cm.path.parent, cm.name
    try:
        sources = {f"{name}.c": (directory / f"{name}.c").read_text(),
                   f"{name}.h": (directory / f"{name}.h").read_text()}
    except OSError as exc:
        raise SimulationError(f"{name}: the generated sources are not next to {cm.path} "
                              f"({exc.strerror or exc}); fix: load the model again so "
                              f"they are rewritten") from None
    expected = cm.manifest.get("sources_sha256", {})
    if any(expected.get(fname) != hashlib.sha256(text.encode()).hexdigest()
           for fname, text in sources.items()):
        # another variant of the model was built into that directory since: its
        # sources are not this build's, so none travel (workers need the shared path)
        sources = None
    return ModelPayload(cm.manifest, str(cm.path), sources,
                        (cm.lib.runtime[0], str(cm.lib.runtime[1])))


_LOADED: dict = {}
_LOCK = threading.Lock()
_BUILDS = {"count": 0}


def builds_in_this_process() -> int:
    """How many models :func:`worker_model` compiled in this process (a test's count)."""
    return _BUILDS["count"]


def worker_model(payload: ModelPayload, build_dir=None) -> CompiledModel:
    """The compiled model of ``payload`` in this process, loaded once and kept: from
    the payload's module path when its build verifies there (a shared file system),
    else from this process's build cache (``build_dir`` or the per-user default),
    compiling the shipped sources there if need be: at most once per process."""
    key = payload.build_hash
    with _LOCK:
        cm = _LOADED.get(key)
        if cm is not None:
            return cm
        manifest, path = payload.manifest, Path(payload.module_path)
        hit = cache_lookup(path.parent, key)[0] if path.is_file() else None
        if hit is None:
            directory = Path(build_dir) if build_dir else default_output(manifest["name"])
            hit = cache_lookup(directory, key)[0]
            if hit is None and payload.sources is None:
                raise SimulationError(
                    f"{manifest['name']}: {path} is not reachable from this worker and the "
                    f"model's sources could not be shipped (another variant was built into "
                    f"its directory since); fix: build the model into a directory of its own "
                    f"(build_dir=...) or share the build directory with the workers")
            if hit is None:
                from modelgen.codegen.emit import integrator_sources
                from modelgen.codegen.pipeline import part_statements
                statements = part_statements({name: o["statements"]
                                              for name, o in manifest["ops"].items()})
                keep = {k: v for k, v in manifest.items()
                        if k not in ("module_name", "module_file", "module_size", "module_sha256",
                                     "manifest_sha256", "compile_commands", "integrators",
                                     "seconds")}
                hit = build_module(directory, manifest["name"], payload.sources, keep,
                                   statements, integrator_sources())
                _BUILDS["count"] += 1
        # the runtime module the driver named, when intact here: finding it otherwise
        # renders its sources, which imports the code generator
        cm = unpickled(hit.manifest, str(hit.module_path), payload.runtime)
        _LOADED[key] = cm
        return cm


# -- one chunk ---------------------------------------------------------------------------

@dataclass(frozen=True)
class Study:
    """A sweep's runs, resolved: initial states ``X0`` (n_runs, nx), parameter rows
    ``P`` (n_runs, np), times and integrator settings."""
    X0: np.ndarray
    P: np.ndarray
    t_span: tuple
    t_eval: np.ndarray
    method: str
    rtol: float
    atol: float
    step: float | None
    max_steps: int
    u: object
    outputs: bool

    @property
    def n_runs(self) -> int:
        return self.X0.shape[0]


def run_chunk(model, study: Study, lo: int, hi: int) -> dict:
    """Runs ``lo:hi`` of ``study`` in one :meth:`~CompiledModel.simulate_batch` call on
    ``model`` (a :class:`CompiledModel`, or a :class:`ModelPayload` loaded with
    :func:`worker_model`); plain arrays: ``y`` (runs, nx, times), ``outputs``
    (runs, times, ny) or None, ``status``, ``message``, counters, ``t_reached``,
    ``seconds``.  A run with a non-finite initial value or parameter fails alone, not
    run: status BAD_ARGUMENT, its message naming the values."""
    start = time.perf_counter()
    cm = model if isinstance(model, CompiledModel) else worker_model(model)
    X0, P = study.X0[lo:hi], study.P[lo:hi]
    ok = np.isfinite(X0).all(axis=1) & np.isfinite(P).all(axis=1)
    n, nt, ny = hi - lo, len(study.t_eval), len(cm.output_columns) if study.outputs else 0
    out = {"outputs": None, "message": [""] * n}
    if not ok.all():        # simulate_batch would refuse the whole chunk
        bad = STATUS_BY_NAME["BAD_ARGUMENT"].code
        out.update(y=np.full((n, cm.nx, nt), np.nan), status=np.full(n, bad, np.int32),
                   outputs=np.full((n, nt, ny), np.nan) if ny else None,
                   t_reached=np.full(n, study.t_span[0]),
                   **{name: np.zeros(n, dtype=np.int64) for name in COUNTERS})
        names, rows = [*cm.state_names, *cm.parameters], np.hstack([X0, P])
        for r in np.flatnonzero(~ok):
            out["message"][r] = "Not run: not finite: " + ", ".join(
                f"{names[j]} = {rows[r, j]}" for j in np.flatnonzero(~np.isfinite(rows[r])))
    if ok.any():
        res = cm.simulate_batch(X0[ok], study.t_span, t_eval=study.t_eval, method=study.method,
                                rtol=study.rtol, atol=study.atol, u=study.u, P=P[ok],
                                step=study.step, max_steps=study.max_steps,
                                outputs=study.outputs)
        got = {"y": res.y, "status": np.asarray(res.status, np.int32),
               "t_reached": res.info["t_reached"],
               **{name: np.asarray(getattr(res, name), np.int64) for name in COUNTERS}}
        if ny:      # recorded by the C at every sample
            got["outputs"] = np.concatenate([res.outputs[k] for k in cm.outputs], axis=2)
        if ok.all():            # no copy when every run ran
            out.update(got)
        for key, a in got.items() if not ok.all() else ():
            out[key][ok] = a
        for r, message in zip(np.flatnonzero(ok), res.message):
            out["message"][r] = message
    out["seconds"] = time.perf_counter() - start
    out["pid"] = os.getpid()
    return out


# -- the sweep ---------------------------------------------------------------------------

def _swept(values, argument: str, what: str, example: str) -> dict:
    """``values`` (``parameters`` or ``initial``): a mapping of names to one value or a
    1-D array of them, as float arrays; checked before the model is loaded."""
    if values is None:
        return {}
    if not isinstance(values, Mapping):
        raise ArgumentTypeError(f"{argument} must map {what} names to values, got "
                                f"{values!r:.80}; fix: give a dict, e.g. {argument}={example}")
    out = {}
    for name, value in values.items():
        out[name] = _row(value, f"{what} {name!r}",
                         "one value or a non-empty 1-D array of one value per run",
                         f"e.g. {argument}={example}")
    return out


def _columns(values: dict, names, what: str, n_runs: int | None, other: tuple) -> tuple:
    """(dict name -> float array, n_runs) from :func:`_swept`'s arrays, their names checked
    against the model's; ``other``: (names, what, argument) where the other kind belongs."""
    out = {}
    for name, a in values.items():
        if name not in names:
            hint = f"{name!r} is a {other[1]}: give it in {other[2]}=; " if name in other[0] else ""
            raise ArgumentValueError(f"unknown {what} {name!r}; {hint}{what}s are "
                                     f"{', '.join(names) or 'none'}")
        out[name] = a
    for name, a in out.items():
        if a.size != 1:
            if n_runs not in (None, a.size):
                raise SimulationError(f"{what} {name!r} has {a.size} values, others "
                                      f"{n_runs}; fix: give every swept name one value per "
                                      f"run (modelgen.grid makes a product)")
            n_runs = a.size
    return out, n_runs


def _study(cm, defaults, parameters, initial, x0, t_eval, t_span, method, rtol, atol, step,
           max_steps, u, outputs) -> tuple:
    """(Study, swept coordinates) from a sweep's arguments and the source's defaults."""
    params, n_runs = _columns(parameters, tuple(cm.parameters), "parameter", None,
                              (cm.state_names, "state", "initial"))
    inits, n_runs = _columns(initial, cm.state_names, "state", n_runs,
                             (tuple(cm.parameters), "parameter", "parameters"))
    n_runs = 1 if n_runs is None else n_runs
    base = cm.neutral_state() if x0 is None and "x0" not in defaults else \
        np.array(defaults["x0"] if x0 is None else x0, dtype=float)
    if base.shape != (cm.nx,):
        raise SimulationError(f"{cm.name}: x0 must have {cm.nx} values, got {base.shape}")
    X0 = np.tile(base, (n_runs, 1))
    for name, a in inits.items():
        X0[:, cm.state_names.index(name)] = a
    P = np.tile(cm.params(None), (n_runs, 1))
    for name, a in params.items():
        P[:, list(cm.parameters).index(name)] = a
    if cm.manifest.get("constraints"):
        X0 = _assembled(cm, X0, P, {**inits, **params})
    if t_eval is None:
        if "t_eval" not in defaults:
            raise SimulationError(f"{cm.name}: give t_eval (the sample times); a scene "
                                  f"gives its own")
        t_eval, t_span = defaults["t_eval"], defaults["t_span"] if t_span is None else t_span
    t_eval = np.ascontiguousarray(np.atleast_1d(np.asarray(t_eval, dtype=float)))
    if t_span is None:
        t_span = (float(t_eval[0]), float(t_eval[-1]))
    method = method_of(method or defaults.get("method", "dop853")).name
    if step is None and not method_of(method).adaptive:
        step = defaults.get("step")
        if step is None:
            raise SimulationError(f"method {method!r} has a fixed step: give step=")
    # as simulate: a fixed step gets the steps its span needs (recorded in the attrs)
    max_steps = step_budget(max_steps, DEFAULT_MAX_STEPS if max_steps is None else max_steps,
                            float(step or 0.0), float(t_span[0]), float(t_span[1]))
    study = Study(X0=np.ascontiguousarray(X0), P=np.ascontiguousarray(P),
                  t_span=tuple(float(v) for v in t_span), t_eval=t_eval, method=method,
                  rtol=defaults.get("rtol", 1e-8) if rtol is None else rtol,
                  atol=defaults.get("atol", 1e-10) if atol is None else atol,
                  step=step, max_steps=max_steps, u=defaults.get("u") if u is None else u,
                  outputs=bool(outputs))
    # a parameter named as one of the dataset's own names (time, run, status, a state, an
    # initial_<state>) is parameter_<name>: overwriting those would lose data silently
    fixed = {"run", "time", "status", "message", "t_reached", *COUNTERS, *cm.state_names}
    own = fixed | {*cm.outputs, *(f"{o}_column" for o in cm.outputs),
                   *(f"initial_{s}" for s in inits)}
    if study.outputs and fixed & set(cm.outputs):
        raise SimulationError(f"{cm.name}: the outputs {sorted(fixed & set(cm.outputs))} are named "
                              f"as the dataset's own variables; fix: rename them, or outputs=False")
    swept = {(f"parameter_{name}" if name in own else name): ("parameter", name, a)
             for name, a in params.items()}
    swept.update({f"initial_{name}": ("initial value of", name, a) for name, a in inits.items()})
    return study, swept


def _assembled(cm, X0, P, swept: dict) -> np.ndarray:
    """``X0`` of a constrained model with every run put on the constraints with its own
    parameters: the dependent coordinates assembled (Newton from their given values)
    with every other coordinate as given, so a swept one keeps its value, then the
    dependent speeds from the independent ones (docs/constraints.md, "Sweeps").  A
    swept dependent coordinate or speed is refused: assembly would overwrite it."""
    info = cm.manifest["constraints"]
    dep = [cm.coordinates[k] for k in info["dependent_coordinates"]] + \
        [cm.speeds[k] for k in info["dependent_speeds"]]
    clash = [name for name in swept if name in dep]
    if clash:
        free = [name for name in cm.state_names if name not in dep]
        raise ArgumentValueError(
            f"{cm.name}: the initial {clash[0]} is swept, but it is a dependent state: each "
            f"run starts on the constraints with {', '.join(dep)} computed from the others; "
            f"fix: sweep independent ones ({', '.join(free)}), or declare other dependent "
            "coordinates and speeds ('dependent:' in the model)")
    keep = [c for c in cm.coordinates if c not in dep]
    nq, nx = cm.nq, cm.nx
    # identical rows (a parameter swept that the constraints do not involve still
    # repeats the state) are assembled once
    unique, inverse = np.unique(np.hstack([X0, P]), axis=0, return_inverse=True)
    inverse = inverse.reshape(-1)
    out = np.empty((unique.shape[0], nx))
    for i, row in enumerate(unique):
        if not np.all(np.isfinite(row)):    # not run: run_chunk reports it
            out[i] = row[:nx]
            continue
        try:
            q = cm.assemble(row[:nq], keep=keep, p=row[nx:])
            out[i] = np.concatenate([q, cm.consistent_speeds(q, row[nq:nx], row[nx:])])
        except SimulationError as exc:
            r = int(np.flatnonzero(inverse == i)[0])
            values = ", ".join(f"{name} = {a[r] if a.size > 1 else a[0]:.6g}"
                               for name, a in swept.items())
            raise SimulationError(
                f"{cm.name}: run {r} ({values or 'the given x0'}) cannot start on the "
                f"constraints: {exc}; fix: sweep values the mechanism can take (or give an "
                "x0 nearer an assembled state)") from None
    return np.ascontiguousarray(out[inverse])


def check_client(client, name: str = "client") -> None:
    """Refuse, before anything is built, a ``client`` that is none of None, ``"local"``,
    a scheduler's address (``tcp://HOST:PORT``, only parsed) or a ``Client``;
    ``name`` names it in the message (``--scheduler`` on the command line)."""
    if client is None or (isinstance(client, str) and client == "local"):
        return
    if not isinstance(client, str) and all(hasattr(client, a) for a in (
            "scheduler", "nthreads", "scatter", "submit")):
        return      # a Client, or one that works as one (by what a sweep calls on it)
    forms = ("'local' (a cluster on this machine) or a scheduler's address tcp://HOST:PORT, "
             "e.g. tcp://127.0.0.1:8786")
    if name == "client":
        forms += ", or a dask.distributed.Client"
    if not isinstance(client, str):
        raise ArgumentTypeError(f"{name} must be a string or a Client, got {client!r:.80}; "
                                f"fix: give {forms}")
    distributed = require("distributed")
    try:
        distributed.comm.get_address_host_port(client)     # the scheme, host and port
    except (ValueError, TypeError) as exc:
        raise ArgumentValueError(f"{name} {client!r} is not a Dask scheduler address ({exc}); "
                                 f"fix: give {forms}") from None


def _client(client):
    """``(client, owned)``: a Client from ``"local"``, an address or a Client (checked
    by :func:`check_client` before the model was loaded)."""
    if client is None:
        return None, False
    distributed = require("distributed")
    if isinstance(client, str):
        if client == "local":
            cluster = distributed.LocalCluster(n_workers=os.cpu_count() or 1,
                                               threads_per_worker=1, processes=True,
                                               dashboard_address=None)
            return distributed.Client(cluster), True
        try:
            return distributed.Client(client), True
        except OSError as exc:          # distributed's connection timeout names no path
            raise ModelgenError(f"could not reach the Dask scheduler at {client!r}: {exc}; "
                                f"fix: start the scheduler there (dask scheduler) or check "
                                f"the address, or use 'local' for a cluster on this "
                                f"machine") from None
    return client, False


def _chunks(n_runs: int, chunk: int | None, parts: int) -> list:
    size = chunk if chunk is not None else max(1, math.ceil(n_runs / max(parts, 1)))
    return [(lo, min(lo + size, n_runs)) for lo in range(0, n_runs, size)]


def _count(value, what: str, fix: str) -> int:
    """``value`` as a whole number >= 1 (``chunk``, ``max_steps``), before the model loads."""
    try:
        count = whole_number(value, what)
    except (ArgumentTypeError, ArgumentValueError) as exc:
        raise type(exc)(f"{exc}; fix: {fix}") from None
    if count < 1:
        raise ArgumentValueError(f"{what} must be >= 1, got {value!r}; fix: {fix}")
    return count


def sweep(source, parameters=None, initial=None, *, t_eval=None, t_span=None, method=None,
          rtol=None, atol=None, step=None, max_steps=None, u=None, x0=None, client=None,
          chunk=None, outputs=True, progress=None, build_dir=None):
    """Run ``source`` over swept parameters and initial values; an ``xarray.Dataset``.

    ``source``: a scene file (or :class:`Scene`; it gives the defaults of
    ``t_eval``, ``t_span``, ``method``, ``rtol``, ``atol``, ``step``, ``u``, ``x0``),
    a model file (or spec) or a :class:`CompiledModel` (``x0`` default zeros;
    give ``t_eval``).  ``parameters`` and ``initial`` map parameter and state
    names (``q1_dot``) to one value or one per run (:func:`grid`, or paired
    samples).  A constrained model's runs start on its constraints with their own
    parameters (dependent states computed; sweeping one is refused).  ``client``:
    None (in-process), a ``dask.distributed.Client``, an address or ``"local"``
    (a ``LocalCluster``, one worker per core).  ``chunk``: runs per
    ``simulate_batch`` call (default: :data:`PROGRESS_CHUNKS` chunks in-process, or
    :data:`CHUNKS_PER_WORKER` per worker thread; Ctrl-C stops a call within a
    step).  ``max_steps`` defaults as in ``simulate`` (100,000, or what a fixed
    ``step`` needs).  ``progress(done, total)`` is called as runs finish.  A
    sweep whose results exceed this machine's memory is refused before any run.

    The dataset: dims ``run`` and ``time`` (s); a variable per state and scene
    output (several columns: a ``<name>_column`` dim); the swept values as
    coordinates along ``run`` (a parameter by its name, ``parameter_<name>`` if
    that is one of the dataset's; initial values as ``initial_<state>``); per
    run ``status`` (< 0 failed; BAD_ARGUMENT: not run, a swept value not
    finite), ``message``, ``t_reached`` (s), ``nfev``, ``naccept``, ``nreject``;
    a ``description`` on each; settings and timings in ``attrs`` (``seconds``,
    ``load_seconds``, ``compute_seconds``, ``workers``, ``chunks``, ``chunk``,
    ``scheduler``: all that differs between repeats).

    >>> ds = sweep("models/double_pendulum.yaml", initial={"q1": np.linspace(0, 1, 100)},
    ...            t_eval=np.linspace(0, 10, 101))                          # doctest: +SKIP
    """
    xr = require("xarray")
    start = time.perf_counter()
    # the arguments that need no model are checked before it is loaded (or built)
    parameters = _swept(parameters, "parameters", "parameter", "{'g': [9.7, 9.8, 9.9]}")
    initial = _swept(initial, "initial", "state", "{'q1': np.linspace(0.1, 3.0, 32)}")
    if t_eval is not None:
        t_eval = _real_array(t_eval, "t_eval", "np.linspace(0.0, 10.0, 101)")
    if x0 is not None:
        x0 = _real_array(x0, "x0", "[0.1, 0.0, 0.0, 0.0]")
    if method is not None:
        method_of(method)
    if chunk is not None:
        chunk = _count(chunk, "chunk", "give the runs per simulate_batch call, or None")
    if max_steps is not None:
        max_steps = _count(max_steps, "max_steps", "give the most steps of a run, e.g. 100000")
    if progress is not None and not callable(progress):
        raise ArgumentTypeError(f"progress must be None or a callable, got {progress!r:.80}; "
                                f"fix: give a function progress(done, total)")
    check_client(client)
    cm, defaults = load_model(source, build_dir)
    study, swept = _study(cm, defaults, parameters, initial, x0, t_eval, t_span, method, rtol,
                          atol, step, max_steps, u, outputs)
    _check_memory(cm, study)
    loaded = time.perf_counter()
    dask_client, owned = _client(client)
    scheduler = "in-process" if dask_client is None else \
        str(getattr(dask_client.scheduler, "address", None) or "dask")
    try:
        if dask_client is None:
            bounds = _chunks(study.n_runs, chunk, PROGRESS_CHUNKS)
            results, workers = [], 1
            with warnings.catch_warnings():     # one warning for the sweep, below
                warnings.filterwarnings("ignore", ".*runs reached max_steps", RuntimeWarning)
                for lo, hi in bounds:
                    results.append(run_chunk(cm, study, lo, hi))
                    if np.any(results[-1]["status"] == INTERRUPTED):   # Ctrl-C in the C
                        raise KeyboardInterrupt
                    if progress:
                        progress(hi, study.n_runs)
        else:
            results, workers, bounds = _distributed(dask_client, cm, study, chunk, progress)
    finally:
        if owned:
            cluster = getattr(dask_client, "cluster", None)
            dask_client.close()
            if cluster is not None:
                cluster.close()
    ds = _dataset(xr, cm, study, swept, results, defaults, dict(
        seconds=time.perf_counter() - loaded, load_seconds=loaded - start, workers=workers, chunks=len(bounds),
        chunk=max(hi - lo for lo, hi in bounds) if bounds else 0,
        compute_seconds=float(sum(r["seconds"] for r in results)), scheduler=scheduler))
    short = int(np.count_nonzero(ds["status"].values == STATUS_BY_NAME["MAX_STEPS"].code))
    if short:
        warnings.warn(f"{cm.name}: {short} of {study.n_runs} runs reached max_steps "
                      f"({study.max_steps}); see their messages", RuntimeWarning, stacklevel=2)
    return ds


def physical_memory() -> float:
    """This machine's memory in bytes (inf where the system does not say)."""
    try:
        return float(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (AttributeError, ValueError, OSError):
        return math.inf


def _check_memory(cm, study) -> None:
    # before any run: chunk by chunk, a sweep too large would run for hours, then fail
    # (or be killed) assembling its results, held twice (the chunks' and the dataset's)
    columns = cm.nx + (len(cm.output_columns) if study.outputs else 0)
    need, have = 16.0 * study.n_runs * len(study.t_eval) * columns, physical_memory()
    if need > have:
        raise ArgumentValueError(
            f"{cm.name}: the sweep's results ({study.n_runs} runs x {len(study.t_eval)} samples x "
            f"{columns} columns, held twice) need {need / 1e9:.3g} GB, more than this machine's "
            f"{have / 1e9:.3g} GB; fix: fewer samples in t_eval, fewer runs, or outputs=False")


def _distributed(client, cm, study, chunk, progress) -> tuple:
    """Scatter the model and the study once, run one task per chunk; results in order."""
    distributed = require("distributed")
    threads = sum(client.nthreads().values()) or 1
    bounds = _chunks(study.n_runs, chunk, CHUNKS_PER_WORKER * threads)
    payload = client.scatter(payload_of(cm), broadcast=True)
    shared = client.scatter(study, broadcast=True)
    futures = [client.submit(run_chunk, payload, shared, lo, hi, pure=False)
               for lo, hi in bounds]
    index = {f.key: k for k, f in enumerate(futures)}
    results = [None] * len(futures)
    done = 0
    try:
        for future in distributed.as_completed(futures):
            k = index[future.key]
            results[k] = future.result()
            done += bounds[k][1] - bounds[k][0]
            if progress:
                progress(done, study.n_runs)
    except BaseException:   # Ctrl-C: a kept traceback keeps the futures (and the cluster busy)
        client.cancel([*futures, payload, shared])
        raise
    return results, len(client.nthreads()), bounds


def _dataset(xr, cm, study, swept, results, defaults, timing):
    """The sweep's ``xarray.Dataset`` from its chunks' results, in run order."""
    coords = {"run": np.arange(study.n_runs), "time": study.t_eval}
    for name, (_, _, values) in swept.items():
        coords[name] = ("run", np.broadcast_to(values, (study.n_runs,)).copy())
    # one contiguous block per state, filled chunk by chunk (one copy): xarray is slow on
    # strided views (6.8 s instead of 0.02 s for four 10,000 x 101 views, xarray 2026.9)
    by_state = np.empty((cm.nx, study.n_runs, len(study.t_eval)))
    lo = 0
    for r in results:
        hi = lo + r["y"].shape[0]
        by_state[:, lo:hi] = r["y"].transpose(1, 0, 2)
        lo = hi
    data = {name: (("run", "time"), by_state[i]) for i, name in enumerate(cm.state_names)}
    if study.outputs and cm.output_columns:
        ys = np.concatenate([r["outputs"] for r in results])
        for name, cols in cm.outputs.items():
            idx = [cm.output_columns.index(c) for c in cols]
            if len(cols) == 1:
                data[name] = (("run", "time"), np.ascontiguousarray(ys[:, :, idx[0]]))
            else:
                dim = f"{name}_column"
                coords[dim] = list(cols)
                data[name] = (("run", "time", dim), ys[:, :, idx])
    per_run = {name: np.concatenate([r[name] for r in results])
               for name in ("status", *COUNTERS, "t_reached")}
    per_run["message"] = np.array([m for r in results for m in r["message"]], dtype=str)
    data.update({name: ("run", values) for name, values in per_run.items()})
    attrs = {"model": cm.name, "scene": defaults.get("scene", ""), "method": study.method,
             "rtol": float(np.max(study.rtol)), "atol": float(np.max(study.atol)),
             "step": float(study.step or 0.0), "t_span": list(study.t_span),
             "max_steps": study.max_steps, "build_hash": cm.manifest["build_hash"],
             "modelgen_version": __version__, "swept": " ".join(swept),
             "runs": study.n_runs, "failed": int(np.count_nonzero(per_run["status"] < 0)),
             **timing}
    ds = xr.Dataset(data, coords=coords, attrs=attrs)
    about = {"time": "sample time", "t_reached": "time the run reached: t_span's end, or where "
             "it failed", "status": "0 success, 1 stopped by an event, < 0 failed (modelgen.sim."
             "integrate.STATUS; message says why)", "message": "the integrator's message",
             "nfev": "right-hand side evaluations", "naccept": "accepted steps",
             "nreject": "rejected steps", **{name: f"swept {kind} {of}" for name, (kind, of, _)
                                             in swept.items()},
             **{name: f"scene output {name}" for name in cm.outputs if name in ds}}
    # the model's units; a swept parameter's or initial value's: its name's in the model
    units = {**cm.units, **{n: cm.units.get(of, "") for n, (_, of, _) in swept.items()},
             "time": "s", "t_reached": "s"}
    for name, text in {**about, **{x: f"state {x}" for x in cm.state_names}}.items():
        ds[name].attrs.update(description=text)
        ds[name].attrs.update({"kind": "state"} if name in cm.state_names else {})
        ds[name].attrs.update({"units": units[name]} if units.get(name) else {})
    return ds
