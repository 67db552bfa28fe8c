"""Which C compiler a build runs, for flags only one compiler knows."""
from __future__ import annotations

import functools

#: Added to an optimised level when the compiler is gcc: its dead-store passes,
#: which find no dead store in generated code (the same machine code with and
#: without, up to the stack slots of spills, on the 20- and 50-link chains with
#: their derivatives), but walk the aliasing stores behind each of the many
#: stores of a large routine (a seventh of the compile time of the derivatives'
#: part).  clang has no such flags.
GCC_FLAGS = ("-fno-tree-dse", "-fno-dse")


@functools.lru_cache(maxsize=4)
def is_gcc(command: tuple) -> bool:
    """True if the C compiler ``command`` is gcc (its ``--version`` names the Free
    Software Foundation; clang, Apple's cc and Intel's icx do not); False if it
    does not run.

    >>> is_gcc(("no-such-compiler-xyz",))
    False
    """
    import subprocess     # imported by a build only (a cached load needs none)
    try:
        out = subprocess.run([*command, "--version"], capture_output=True, text=True,
                             timeout=30).stdout
    except (OSError, subprocess.SubprocessError):
        return False
    return "Free Software Foundation" in out
