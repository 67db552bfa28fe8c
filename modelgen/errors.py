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
    """The C compiler failed.

    ``command`` is the full command line and ``output`` the compiler's complete
    output; both are part of the message.
    """

    def __init__(self, message: str, command: list[str] | None = None,
                 output: str = ""):
        self.command = list(command or [])
        self.output = output
        text = message
        if self.command:
            text += "\ncommand: " + " ".join(self.command)
        if output:
            text += "\ncompiler output:\n" + output
        super().__init__(text)


class SimulationError(ModelgenError):
    """Invalid arguments to a run-time call (wrong shapes, NaN parameters...)."""


class MassMatrixError(SimulationError):
    """The mass matrix is not positive definite, or singular to working precision,
    at the given state (``kind`` says which)."""

    def __init__(self, pivot: int, coordinate: str, t, x, kind: str = "not positive definite"):
        self.pivot, self.coordinate, self.t, self.x, self.kind = pivot, coordinate, t, x, kind
        super().__init__(
            f"mass matrix {kind} at t={t!r}: Cholesky pivot {pivot} "
            f"(coordinate {coordinate!r}) failed; state x=[{', '.join(repr(float(v)) for v in x)}]")
