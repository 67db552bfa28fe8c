"""Exceptions raised by modelgen.

Every error modelgen raises on purpose derives from :class:`ModelgenError`, so
callers can catch the whole family with one ``except`` clause.
"""
from __future__ import annotations


class ModelgenError(Exception):
    """Base class of every error raised by modelgen."""


class ModelError(ModelgenError):
    """A model or scene description is invalid.

    The message names the file, the line, the key and the offending name, and
    says how to fix it.  The pieces are kept as attributes for programs.

    >>> e = ModelError("unknown base 'B9'", file="m.yaml", line=4,
    ...                key="bases.B2.parent", fix="declare B9 under 'bases'")
    >>> str(e)
    "m.yaml:4: bases.B2.parent: unknown base 'B9'; fix: declare B9 under 'bases'"
    """

    def __init__(self, problem: str, *, file: str | None = None,
                 line: int | None = None, key: str | None = None,
                 fix: str | None = None):
        self.problem = problem
        self.file = file
        self.line = line
        self.key = key
        self.fix = fix
        super().__init__(self._format())

    def _format(self) -> str:
        where = self.file if self.file is not None else "<model>"
        if self.line is not None:
            where += f":{self.line}"
        text = f"{where}: "
        if self.key:
            text += f"{self.key}: "
        text += self.problem
        if self.fix:
            text += f"; fix: {self.fix}"
        return text


class ExpressionError(ModelgenError):
    """An expression string could not be parsed.

    Raised by :mod:`modelgen.model.expr`; the model loader re-raises it as a
    :class:`ModelError` carrying the file, line and key.
    """


class DerivationError(ModelgenError):
    """The equations of motion cannot be derived (e.g. A is singular by construction)."""


class TemplateError(ModelgenError):
    """A jinja2 template failed to render."""


class BuildError(ModelgenError):
    """The module could not be built: no usable compiler, a compiler that failed,
    an output directory that cannot be written, or a damaged build.

    ``command`` is the full command line, ``returncode`` its exit status (None
    when it never ran), ``output`` the compiler's complete output and ``fix``
    what to do; all of them are part of the message.

    >>> print(BuildError("C compiler not found", ["cc", "-c", "m.c"],
    ...                  fix="install a C compiler or set CC"))
    C compiler not found; fix: install a C compiler or set CC
    command: cc -c m.c
    """

    def __init__(self, message: str, command: list[str] | None = None,
                 output: str = "", *, returncode: int | None = None,
                 fix: str | None = None):
        self.command = list(command or [])
        self.output = output
        self.returncode = returncode
        self.fix = fix
        text = message
        if fix:
            text += f"; fix: {fix}"
        if self.command:
            text += "\ncommand: " + " ".join(self.command)
        if returncode is not None:
            text += f"\nexit status: {returncode}"
        if output:
            text += "\ncompiler output:\n" + output
        super().__init__(text)


class SimulationError(ModelgenError):
    """Invalid arguments to a run-time call (wrong shapes, NaN parameters...)."""


class ArgumentTypeError(SimulationError, TypeError):
    """An argument of the Python API of the wrong type (``events=42``, an event's
    ``terminal = "yes"``, an ``out=`` array of integers, a feedback ``u`` that
    returns None): ``except TypeError`` catches it too, as with scipy's
    ``solve_ivp``."""


class ArgumentValueError(SimulationError, ValueError):
    """An argument of the Python API of the right type but a wrong value (an
    event's ``terminal = -1``, ``max_steps=2.5``, an ``out=`` array of the wrong
    shape): ``except ValueError`` catches it too, as with scipy's ``solve_ivp``."""


class MassMatrixError(SimulationError):
    """The mass matrix is not positive definite, or singular to working precision,
    at the given state (``kind`` says which)."""

    def __init__(self, pivot: int, coordinate: str, t, x, kind: str = "not positive definite"):
        self.pivot, self.coordinate, self.t, self.x, self.kind = pivot, coordinate, t, x, kind
        super().__init__(
            f"mass matrix {kind} at t={t!r}: pivot {pivot} "
            f"(coordinate {coordinate!r}) failed; state x=[{', '.join(repr(float(v)) for v in x)}]")
