"""Parts of a model's C compiled early, while Python still eliminates the rest.

A model's ``<name>.c`` is compiled once per part (``-DMG_PART=k``, see
:data:`modelgen.codegen.build.OPT_LEVELS`), and parts 2, 3 and 4 are ready to
compile before the rest of the file is: they hold only the routines
eliminated on their own (the rhs, the derivatives' straight line, the
inverse dynamics), which come before the routines that share one
elimination (the mass matrix, the energies...), see
:class:`modelgen.codegen.pipeline._EarlyStart`.  :func:`start` compiles a part
from a file rendered with the routines known so far (the others empty);
:meth:`EarlyPart.matches` keeps its object only when the final file gives
the part the same text (:func:`part_text`), the same headers and the same
command, so the library is always the final file compiled; if anything
differs, or the text cannot be told, the object is discarded and the part
compiled again with the others.  The compilers then run on the cores the
elimination leaves.
"""
from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

from modelgen.codegen.build import private_dir
from modelgen.codegen.compilers import command_failure, start_command
from modelgen.errors import BuildError

#: The first and last line of a block that only part k compiles (model.c.j2,
#: kinematics.c.j2): ``#if !defined(MG_PART) || MG_PART == k`` ...
#: ``#endif /* MG_PART k ... */``.
_BEGIN = re.compile(r"#if !defined\(MG_PART\) \|\| MG_PART == (\d+)\s*$")
_END = re.compile(r"#endif /\* MG_PART (\d+)\b")


def part_text(source: str, part: int) -> str | None:
    """What a compile of ``source`` with ``-DMG_PART=part`` reads: ``source``
    without the blocks of the other parts (None if its blocks do not pair up,
    which the templates never write: then nothing is assumed).

    >>> src = ("a\\n#if !defined(MG_PART) || MG_PART == 1\\nb\\n#endif /* MG_PART 1 */\\n"
    ...        "#if !defined(MG_PART) || MG_PART == 2\\nc\\n#endif /* MG_PART 2 */\\n")
    >>> part_text(src, 2).split()
    ['a', '#if', '!defined(MG_PART)', '||', 'MG_PART', '==', '2', 'c', '#endif', '/*', 'MG_PART', '2', '*/']
    """
    out, skipping = [], None
    for line in source.splitlines(keepends=True):
        begin = _BEGIN.match(line)
        if skipping is None:
            if begin and int(begin[1]) != part:
                skipping = int(begin[1])
            else:
                out.append(line)
        elif begin:
            return None
        else:
            end = _END.match(line)
            if end:
                if int(end[1]) != skipping:
                    return None
                skipping = None
    return None if skipping is not None else "".join(out)


class EarlyPart:
    """The compile of one part, started by :func:`start`."""

    def __init__(self, part: int, command: list, texts: dict, tmp: Path,
                 proc: subprocess.Popen):
        self.part, self.command, self.texts = part, command, texts
        self.tmp, self.proc = tmp, proc

    def matches(self, sources: dict, name: str, command: list) -> bool:
        """True if the final ``sources`` (file name -> text) and ``command`` of the
        part are those it compiles (a text :func:`part_text` cannot tell is
        not); else it is stopped."""
        known = self.texts.get(f"{name}.c") is not None
        if known and command == self.command and _texts(sources, name, self.part) == self.texts:
            return True
        self.stop()
        return False

    def finish(self, target: Path) -> None:
        """Wait for the compile and move its object to ``target`` (BuildError, as
        for any compile, if it failed)."""
        try:
            failure = command_failure(self.proc, self.command)
            if failure is not None:
                raise failure
            (self.tmp / self.command[-1]).replace(target)
        finally:
            self.stop()

    def stop(self) -> None:
        """End the compile if it still runs and remove its files (again: nothing)."""
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.communicate()
        shutil.rmtree(self.tmp, ignore_errors=True)


def _texts(sources: dict, name: str, part: int) -> dict:
    """What a compile of ``part`` reads of ``sources``: the part's text of
    ``<name>.c`` and the headers whole."""
    return {fname: part_text(text, part) if fname == f"{name}.c" else text
            for fname, text in sources.items()}


def start(directory: Path, name: str, sources: dict, part: int,
          command: list) -> EarlyPart | None:
    """Compile ``part`` of ``sources`` (``<name>.c`` and the headers it includes,
    file name -> text) with ``command`` in a private directory in ``directory``;
    returns at once; None if it cannot start (the build then compiles the part
    with the others, and says why it cannot)."""
    try:
        tmp = private_dir(directory, ".build-")
    except BuildError:
        return None
    try:
        for fname, text in sources.items():
            (tmp / fname).write_text(text)
        proc = start_command(command, tmp)
    except OSError:
        shutil.rmtree(tmp, ignore_errors=True)
        return None
    return EarlyPart(part, command, _texts(sources, name, part), tmp, proc)
