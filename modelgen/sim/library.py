"""Loader: a model's plain shared library, callable from Python through the runtime module.

A built model is a C shared library with no Python in it (see
:mod:`modelgen.codegen.build`).  :class:`ModelLibrary` opens it with
:mod:`ctypes` (only to look its symbols up), and binds each exported function
named in the manifest to the runtime module's cffi trampoline of that
function's signature: ``lib.double_pendulum_rhs(t, x, u, p, out)`` is
``runtime.mg_call_t_x_u_p(<pointer to double_pendulum_rhs>, t, x, u, p, out)``,
a cffi call with one more argument.  Everything else of the runtime module
(the ``MG_*`` constants, ``mg_work_size``) is reachable as an attribute too,
and ``ffi`` is the runtime module's, so structs such as ``mg_options`` are
created with it.

>>> lib = ModelLibrary(manifest, path)                      # doctest: +SKIP
>>> lib.double_pendulum_abi_version() == lib.MG_ABI_VERSION  # doctest: +SKIP
True
"""
from __future__ import annotations

import ctypes
import functools
import importlib.util
import os
import sys
import tempfile
import warnings
from pathlib import Path

from modelgen.codegen.build import manifest_problem
from modelgen.codegen.capi import ABI_VERSION
from modelgen.errors import BuildError
from modelgen.sim.massmatrix import default_parameters


def runtime_module(location: tuple | None = None):
    """The imported runtime module (``ffi``, ``lib``), built on first use.

    ``location`` (module name, path), from the build cache's fast index, spares
    rendering its sources to find it (:mod:`modelgen.codegen.index`); without
    it the codegen stage says where it is, building it if need be.
    """
    location = location if location is not None else _runtime_location()
    try:
        return _import_runtime(*location)
    except ImportError as exc:
        # verified before the import, so rarely reached: rebuild it once, then name it
        from modelgen.codegen.pipeline import runtime
        warnings.warn(f"the runtime module {location[1]} cannot be imported ({exc}); "
                      f"rebuilding it", stacklevel=2)
        location = runtime(rebuild=True)
    try:
        # through a fresh path: the library of the failed import stays loaded under
        # the old one, and the dynamic loader would hand it out again
        with tempfile.TemporaryDirectory(prefix=".import-", dir=location[1].parent) as tmp:
            fresh = Path(tmp) / location[1].name
            os.link(location[1], fresh)
            return _import_runtime(location[0], fresh)
    except (ImportError, OSError) as exc:
        raise BuildError(f"the runtime module {location[1]} cannot be imported ({exc}), "
                         f"even rebuilt", fix=f"delete {location[1]} and report this") from None


@functools.lru_cache(maxsize=None)
def _runtime_location() -> tuple:
    # imported here, not at the top: rendering the runtime's sources needs the
    # codegen stage's emitter, which a model found through the fast index never imports
    from modelgen.codegen.pipeline import runtime
    return runtime()


@functools.lru_cache(maxsize=None)
def _import_runtime(module_name: str, path):
    if module_name in sys.modules:
        return sys.modules[module_name]
    spec = importlib.util.spec_from_file_location(module_name, str(path))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    sys.modules[module_name] = module
    return module


def open_library(manifest: dict, path: Path) -> ctypes.CDLL:
    """The model's shared library at ``path``, opened with :mod:`ctypes`, once its
    manifest's structure and ABI version, and the library's own ABI version and
    sizes, agree with this modelgen and the manifest (every buffer is sized by
    names from the manifest, so a count that differs would overrun one).
    Raises :class:`~modelgen.errors.BuildError` saying to rebuild otherwise."""
    problem = manifest_problem(manifest)
    if problem:
        raise BuildError(f"{path}: {problem}; rebuild the model (force=True)")
    if manifest["abi_version"] != ABI_VERSION:
        raise BuildError(f"{path}: built for ABI version {manifest['abi_version']}, "
                         f"this modelgen expects {ABI_VERSION}; rebuild the model "
                         f"(force=True)")
    try:
        dll = ctypes.CDLL(str(path))
    except OSError as exc:
        raise BuildError(f"{path} cannot be loaded ({exc}); rebuild the model "
                         f"(force=True)") from None
    name = manifest["name"]
    got = _function(dll, path, f"{name}_abi_version")()
    if got != ABI_VERSION:
        raise BuildError(f"{path}: generated ABI version {got}, this modelgen "
                         f"expects {ABI_VERSION}; regenerate the model")
    dims = (ctypes.c_int * 7)()
    _function(dll, path, f"{name}_dimensions")(dims)
    nq, n = len(manifest["coordinates"]), len(manifest.get("speeds") or
                                               manifest["coordinates"])
    expected = {"NQ": nq, "NX": nq + n, "NP": len(manifest["parameters"]),
                "NU": len(manifest["inputs"]), "NBODIES": len(manifest["bodies"]),
                "NY": sum(len(o["columns"]) for o in manifest["outputs"]), "NV": n}
    for got, (key, value) in zip(dims, expected.items()):
        if got != value:
            raise BuildError(f"{path}: the library's {name.upper()}_{key} is {got}, the "
                             f"manifest says {value}; the build is damaged, rebuild "
                             f"the model (force=True)")
    return dll


def mass_matrix_function(manifest: dict, path: Path):
    """``A(q)`` of the model's library at ``path`` with the default parameters, called
    through :mod:`ctypes` alone (no runtime module, cffi or numpy): ``q`` a list
    of ``nq`` floats, A returned as ``n`` lists of ``n`` floats.  What
    :func:`modelgen.sim.massmatrix.check` needs of a library just built.

    >>> A = mass_matrix_function(manifest, path)([0.1, 0.2])   # doctest: +SKIP
    """
    dll = open_library(manifest, path)
    function = _function(dll, path, f"{manifest['name']}_mass_matrix")
    double = ctypes.c_double
    nq, n = len(manifest["coordinates"]), len(manifest.get("speeds") or
                                               manifest["coordinates"])
    p = (double * len(manifest["parameters"]))(*default_parameters(manifest))

    def mass_matrix(q) -> list:
        A = (double * (n * n))()
        function((double * nq)(*q), p, A)
        return [A[i * n:(i + 1) * n] for i in range(n)]
    return mass_matrix


def _function(dll: ctypes.CDLL, path: Path, symbol: str):
    try:
        return getattr(dll, symbol)
    except AttributeError:
        raise BuildError(f"{path}: the library has no function {symbol!r}; rebuild the "
                         f"model (force=True)") from None


class ModelLibrary:
    """The functions of one model's shared library, as cffi callables."""

    def __init__(self, manifest: dict, path: Path, runtime: tuple | None = None):
        """``runtime``: where the runtime module is (see :func:`runtime_module`)."""
        self.path = Path(path)
        self._dll = open_library(manifest, self.path)
        #: (module name, path) of the runtime module: a pickled model names it
        self.runtime = runtime if runtime is not None else _runtime_location()
        module = runtime_module(self.runtime)
        self.ffi, self._runtime = module.ffi, module.lib
        functions = manifest.get("functions")
        if not isinstance(functions, dict):
            raise BuildError(f"{self.path}: the manifest lists no functions; rebuild the "
                             f"model (force=True)")
        for symbol, signature in functions.items():
            trampoline = getattr(self._runtime, f"mg_call_{signature}", None)
            address = self._address(symbol)
            if trampoline is None or not isinstance(symbol, str) or address is None:
                raise BuildError(f"{self.path}: the library has no function {symbol!r} of "
                                 f"signature {signature!r}; rebuild the model (force=True)")
            pointer = self.ffi.cast(f"mg_fn_{signature}", address)
            setattr(self, symbol, functools.partial(trampoline, pointer))

    def unbound(self, symbol: str) -> tuple:
        """(trampoline, function pointer) of ``symbol``, for hot loops that pass
        the pointer themselves (saves the partial's indirection)."""
        bound = getattr(self, symbol)
        return bound.func, bound.args[0]

    def integrate_function(self, name: str, batch: bool = False, backward: bool = False):
        """``<name>_integrate`` (or ``_integrate_batch``); with ``backward`` the same
        integrators on the model reversed in time (``mg_reverse_system``: dx/ds =
        -f(-s, x), so a run from t0 down to t1 < t0 is one from -t0 up to -t1)."""
        if not backward:
            return getattr(self, f"{name}_integrate_batch" if batch else f"{name}_integrate")
        forward = self.ffi.new("mg_system *")
        getattr(self, f"{name}_system")(forward)
        reversed_ = self.ffi.new("mg_system *")
        self._runtime.mg_reverse_system(forward, reversed_)
        bound = functools.partial(self._runtime.mg_integrate_batch if batch
                                  else self._runtime.mg_integrate, reversed_)
        bound.keep = forward                 # reversed_ points at it
        return bound

    def _address(self, symbol):
        try:
            return ctypes.cast(getattr(self._dll, symbol), ctypes.c_void_p).value
        except (AttributeError, TypeError):
            return None

    def __getattr__(self, name):
        # the runtime module's constants (MG_*) and functions (mg_work_size, ...)
        if name.startswith("_"):
            raise AttributeError(name)
        return getattr(self._runtime, name)
