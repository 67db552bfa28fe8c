"""Message helpers shared by the model and scene loaders.

Input: values, names and candidate lists met while validating a file.
Output: the short English phrases of :class:`~modelgen.errors.ModelError`
messages ("the number 3", "a base name", "did you mean ..."), so that every
loader words its errors the same way.
"""
from __future__ import annotations

import difflib
import math
import numbers
from typing import Mapping, Optional

import sympy

__all__ = ["API_FILE", "describe", "listing", "article", "join_and", "closest", "as_list",
           "quote_expression", "comment_text"]

#: ``file`` of the errors raised by the Python API.
API_FILE = "<api>"


#: the longest value :func:`describe` shows whole [characters]; a longer one is cut
SHOWN_LENGTH = 80


def describe(value) -> str:
    """A value's type and value for messages; a long value cut to its start and its
    length (a file read by mistake would otherwise fill the message).

    >>> describe(3), describe([1, 2]), describe(None)
    ('the number 3', 'a list of 2 items', 'null')
    >>> describe("x" * 100)
    "the string 'xxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxx...' (100 characters)"
    """
    if value is None:
        return "null"
    if isinstance(value, bool):
        return f"the boolean {str(value).lower()}"
    if isinstance(value, numbers.Number):
        try:
            return f"the number {_shown(repr(value))}"
        except ValueError:      # Python has no text for an int of more than 4300 digits
            return f"an integer of about {int(int(value).bit_length() * math.log10(2))} digits"
    if isinstance(value, str):
        if len(value) > SHOWN_LENGTH:
            return f"the string {value[:SHOWN_LENGTH - 20] + '...'!r} ({len(value)} characters)"
        return f"the string {value!r}"
    if isinstance(value, Mapping):
        return "a mapping"
    if isinstance(value, (list, tuple)):
        return f"a list of {len(value)} item" + ("" if len(value) == 1 else "s")
    return f"a {type(value).__name__}"


def _shown(text: str) -> str:
    """``text`` whole when short, else its start and its length."""
    if len(text) <= SHOWN_LENGTH:
        return text
    return f"{text[:SHOWN_LENGTH - 20]}... ({len(text)} characters)"


def listing(names, limit: int = 10) -> str:
    """Names joined by commas, at most ``limit``: 'a, b and 3 more', or 'none'.

    >>> listing(['q1', 'q2', 'q3'], limit=2)
    'q1, q2 and 1 more'
    """
    names = list(names)
    if not names:
        return "none"
    if len(names) > limit:
        return ", ".join(names[:limit]) + f" and {len(names) - limit} more"
    return ", ".join(names)


def article(noun: str) -> str:
    """The noun with its indefinite article: 'a base name', 'an input name'.

    >>> article('input name')
    'an input name'
    """
    return ("an " if noun[:1] in "aeiou" else "a ") + noun


def join_and(words) -> str:
    """'a', 'a and b', 'a, b and c'.

    >>> join_and(['mass', 'G', 'base'])
    'mass, G and base'
    """
    words = list(words)
    return words[0] if len(words) == 1 else ", ".join(words[:-1]) + " and " + words[-1]


def closest(word: str, candidates) -> Optional[str]:
    """The candidate closest to ``word`` (for "did you mean ...?"), or None.

    >>> closest('stifness', ['stiffness', 'damping'])
    'stiffness'
    """
    matches = difflib.get_close_matches(word, list(candidates), n=1, cutoff=0.6)
    return matches[0] if matches else None


def as_list(value):
    """A list/tuple (or numpy array, sympy Matrix) as a list; anything else unchanged."""
    if isinstance(value, (list, tuple)):
        return list(value)
    if isinstance(value, sympy.MatrixBase) or (
            hasattr(value, "tolist") and not isinstance(value, (str, sympy.Basic))):
        return value.tolist()
    return value


def quote_expression(value) -> str:
    """An expression as quoted text for a message, shortened past 80 characters."""
    text = value if isinstance(value, str) else repr(value)
    if len(text) > 80:
        text = text[:60] + "..." + text[-15:]
    return repr(text)



def comment_text(text: str) -> str:
    """``text`` made safe to write into one line of a comment or of a terminal report:
    every line break (``\\r \\n \\x85 \\u2028 \\u2029``) and other non-printable
    character as its Python escape.  Names and file names from an imported robot
    go into the model file's ``#`` comments; a raw line break there would end the
    comment and make the rest of the name live YAML.

    >>> print(comment_text("f\\narmature: {j1: 5.0}\\u2028#"))
    f\\narmature: {j1: 5.0}\\u2028#
    """
    if text.isprintable():
        return text
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)
