"""Command-line interface: a thin shell over the library.

``modelgen generate MODEL.yaml [-o DIR]``  writes the C, header and compiled
module and prints n, the operation counts and the time of each stage.

``modelgen sweep SCENE.yaml --param m2=0.5:2:64 --init q1=0.1:3:32 [--scheduler local]``
runs a grid of runs (in-process or on Dask) into a netCDF dataset.

``modelgen simulate SCENE.yaml [-o OUT]``  builds (or reuses) the scene's
reduced model, integrates it in C and writes CSV, NPZ and PNG; given a model
file instead of a scene, integrates it with RK4 from ``--init`` values.

Every command's ``-o`` names the file or directory of its product, and
``--build-dir`` where the model is built (``generate``'s product is the build,
so there the two are one).

Exit status (:data:`EXIT`): 0 success; 2 bad input (a model, scene or
command-line mistake, a value out of range, a result larger than
``--max-output-mb``); 3 a build error (compiler missing or failing); 4 a
simulation that failed (its partial results are still written); 1 an
unexpected internal error; 130 interrupted by Ctrl-C (SIGINT), 143 by SIGTERM
(both keep and write the results so far, marked partial; a second signal
stops at once).  Errors print one line, ``modelgen: error: ...``, with the
fix; ``--debug`` also shows the traceback and keeps the exit status.
"""
from __future__ import annotations

import contextlib
import signal
import sys
import threading

from modelgen.errors import (ArgumentTypeError, ArgumentValueError, BuildError, ModelError,
                             ModelgenError, SimulationError, TemplateError)
from modelgen.cli.commands import EXIT
from modelgen.cli.parsers import build_parser

__all__ = ["main", "build_parser", "EXIT", "exit_status"]


def exit_status(exc: BaseException) -> int:
    """The exit status for an error that ends a command: a wrong argument value or type
    is bad input (2), like a model mistake, even when the simulation layer finds it."""
    if isinstance(exc, (BuildError, TemplateError)):
        return EXIT["build"]
    if isinstance(exc, (ArgumentTypeError, ArgumentValueError)):
        return EXIT["input"]
    if isinstance(exc, SimulationError):
        return EXIT["simulation"]
    if isinstance(exc, (ModelgenError, OSError)):
        return EXIT["input"]
    return EXIT["internal"]


@contextlib.contextmanager
def _terminate_as_interrupt():
    """SIGTERM handled as Ctrl-C, in the main thread: a run stops within a step and its
    results so far are written (the integrator's own SIGINT handler sees it), or a
    KeyboardInterrupt is raised.  Yields a list of the SIGTERMs received."""
    received = []
    if threading.current_thread() is not threading.main_thread():
        yield received
        return

    def on_sigterm(signum, frame):
        received.append(signum)
        if len(received) > 1:       # a second one stops at once
            raise KeyboardInterrupt
        handler = signal.getsignal(signal.SIGINT)
        if callable(handler):       # the integrator's (sets its stop flag) or Python's
            handler(signal.SIGINT, frame)
        else:
            raise KeyboardInterrupt
    previous = signal.signal(signal.SIGTERM, on_sigterm)
    try:
        yield received
    finally:
        signal.signal(signal.SIGTERM, previous)


def _error_text(exc) -> str:
    """One line for an error that ends a command.  A model error from no file (a check
    of an argument deep in the library) leaves out the ``<model>`` placeholder, which
    would name no file the user gave."""
    if not isinstance(exc, ModelgenError):
        return _os_error_text(exc)
    text = str(exc)
    if isinstance(exc, ModelError) and exc.file is None:
        text = text.removeprefix("<model>: ")
    return text


def _os_error_text(exc: OSError) -> str:
    """One line for an operating-system error: what failed, on which path, the fix."""
    import errno
    where = f": {exc.filename}" if exc.filename is not None else ""
    if exc.errno == errno.ENOSPC:
        return (f"no space left on the device{where} (the disk is full); fix: free space "
                f"there or write elsewhere (-o)")
    if exc.filename is None:
        return f"{exc}; fix: check that what it names exists and is reachable"
    return f"{exc.strerror or exc}{where}; fix: check the path and its permissions"


#: The collector's first-generation threshold while the console script runs
#: (Python's default is 700 allocations): a generation allocates millions of
#: short-lived, acyclic sympy objects that reference counting frees, so at the
#: default most young collections find nothing to collect.
CLI_GC_THRESHOLD = 50_000


def run() -> None:
    """The console script and ``python -m modelgen``: :func:`main` in a process of
    its own, then exit with its status.

    Two garbage-collector settings that only a process about to exit may make
    (so never :func:`main`, which tests and scripts call in long-lived processes):
    a first-generation threshold of :data:`CLI_GC_THRESHOLD`, and, before
    exiting, ``gc.freeze()``, which spares the interpreter's shutdown its full
    collections over every object the symbolic packages created (nothing is
    left undone: the atexit handlers run and the modules are cleared as usual).
    The time each saves is in docs/benchmarks.md, "Start-up".
    """
    import gc
    gc.set_threshold(CLI_GC_THRESHOLD, *gc.get_threshold()[1:])
    try:
        status = main()
    finally:
        gc.freeze()
    sys.exit(status)


def main(argv=None) -> int:
    """Entry point; returns the exit status (see :data:`EXIT`)."""
    parser = build_parser()
    args, extra = parser.parse_known_args(argv)
    if extra:     # the subcommand's own usage, not the top-level one
        args.command_parser.error(f"unrecognized arguments: {' '.join(extra)}")
    with _terminate_as_interrupt() as signals:
        try:
            status = args.func(args)
        except KeyboardInterrupt:
            print("modelgen: interrupted", file=sys.stderr)
            status = EXIT["interrupted"]
        except (ModelgenError, OSError) as exc:
            text = _error_text(exc)
            _debug_traceback(args)
            print(f"modelgen: error: {text}", file=sys.stderr)
            status = exit_status(exc)
        except Exception as exc:            # a bug: say so, briefly, unless --debug
            _debug_traceback(args)
            print(f"modelgen: internal error: {type(exc).__name__}: {exc} (please report it; "
                  f"--debug shows the traceback)", file=sys.stderr)
            status = EXIT["internal"]
    if status == EXIT["interrupted"] and signals:
        return EXIT["terminated"]
    return status


def _debug_traceback(args) -> None:
    """With --debug, the traceback of the error being handled (the status is kept)."""
    if args.debug:
        import traceback
        traceback.print_exc()
