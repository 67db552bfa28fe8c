"""Name rules: which strings may name a coordinate, parameter, base, point...

Input: a candidate name (from a file or the Python API).
Output: the name, or a :class:`~modelgen.errors.ModelError` saying why it is
refused and how to fix it.  The rules (see ``docs/model-format.md``, "Names"):
a C identifier of at most :data:`MAX_NAME_LENGTH` characters that is not a C,
C++ or Python keyword, not reserved by modelgen (:data:`MODELGEN_RESERVED`),
and does not start with ``_`` or ``mg_``.  The namespace rules (one namespace
for every declared name, speeds ``<q>_dot``) need the whole model and are
checked by :class:`~modelgen.model.builder.ModelBuilder`.
"""
from __future__ import annotations

import keyword
import re
from typing import Optional

from modelgen.errors import ModelError
from modelgen.model.expr import FUNCTIONS
from modelgen.model.messages import API_FILE, article, describe
from modelgen.model.spec import CANONICAL_BASE, CANONICAL_POINT

__all__ = ["MAX_NAME_LENGTH", "C_KEYWORDS", "CPP_KEYWORDS", "PYTHON_KEYWORDS",
           "MODELGEN_RESERVED", "NAME_RE", "NAME_FIX", "NAMESPACE_NOTE",
           "NAMESPACE_NOTE_EFFECTS", "check_name", "check_model_name",
           "model_name_for"]

#: Longest name accepted (C99 guarantees 63 significant initial characters).
MAX_NAME_LENGTH = 63

C_KEYWORDS = frozenset("""
    auto break case char const continue default do double else enum extern float for
    goto if inline int long register restrict return short signed sizeof static struct
    switch typedef union unsigned void volatile while
    _Bool _Complex _Imaginary _Alignas _Alignof _Atomic _Generic _Noreturn
    _Static_assert _Thread_local
    alignas alignof bool constexpr false nullptr static_assert thread_local true
    typeof typeof_unqual
                       """.split())

CPP_KEYWORDS = frozenset("""
    alignas alignof and and_eq asm auto bitand bitor bool break case catch char char8_t
    char16_t char32_t class compl concept const consteval constexpr constinit const_cast
    continue co_await co_return co_yield decltype default delete do double dynamic_cast
    else enum explicit export extern false float for friend goto if inline int long
    mutable namespace new noexcept not not_eq nullptr operator or or_eq private protected
    public register reinterpret_cast requires return short signed sizeof static
    static_assert static_cast struct switch template this thread_local throw true try
    typedef typeid typename union unsigned using virtual void volatile wchar_t while xor
    xor_eq
                         """.split())

PYTHON_KEYWORDS = frozenset(keyword.kwlist)

#: Names modelgen reserves, with what they mean.
MODELGEN_RESERVED = {
    "t": "time", "pi": "the constant pi",
    CANONICAL_BASE: "the canonical base", CANONICAL_POINT: "the canonical point",
    **{name: "a function" for name in FUNCTIONS},
}

#: A C identifier (the length is checked separately).
NAME_RE = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")
#: How to write a valid name.
NAME_FIX = "use ASCII letters, digits and '_', starting with a letter"
#: The fix of a duplicate name, without and with effects involved.
NAMESPACE_NOTE = ("coordinates, parameters, inputs, bases, points, frames, bodies and "
                  "actions share one namespace")
NAMESPACE_NOTE_EFFECTS = ("coordinates, parameters, inputs, bases, points, frames, bodies, "
                          "actions and effects share one namespace")


def check_name(name, *, file: Optional[str] = API_FILE, line: Optional[int] = None,
               key: Optional[str] = None, what: str = "name",
               modelgen_reserved: bool = True) -> str:
    """Check that ``name`` may name a model entity; return it or raise ModelError.

    Applies the syntax and reserved-word rules of this module's docstring (not
    the namespace rules, which need the whole model).  ``what`` names the
    kind of name in messages; ``modelgen_reserved=False`` skips the
    :data:`MODELGEN_RESERVED` names (used for the model's own name, which is
    a C prefix, not a symbol).

    >>> check_name("q1")
    'q1'
    >>> check_name("int")
    Traceback (most recent call last):
    ...
    modelgen.errors.ModelError: <api>: 'int' is a C keyword; fix: rename it, e.g. 'int1'
    """
    def fail(problem, fix):
        raise ModelError(problem, file=file, line=line, key=key, fix=fix)

    if not isinstance(name, str):
        fix = f"write {article(what)} such as q1 ({NAME_FIX})"
        if isinstance(name, bool):
            fix += "; YAML reads unquoted yes/no/on/off/true/false as booleans, so quote it"
        fail(f"expected {article(what)} but got {describe(name)}", fix)
    if not NAME_RE.match(name):
        fail(f"'{name}' is not a valid {what}", NAME_FIX)
    if len(name) > MAX_NAME_LENGTH:
        fail(f"{what} '{name[:20]}...' is {len(name)} characters long",
             f"use at most {MAX_NAME_LENGTH} characters")
    if name.startswith("_"):
        fail(f"'{name}' starts with '_', which is reserved for generated code",
             "start the name with a letter")
    if name.lower().startswith("mg_"):
        fail(f"'{name}' starts with '{name[:3]}', which is reserved for generated code",
             "choose a name that does not start with 'mg_'")
    if modelgen_reserved and name in MODELGEN_RESERVED:
        fail(f"'{name}' is reserved by modelgen ({MODELGEN_RESERVED[name]})",
             f"rename it, e.g. '{name}1'")
    for words, language in ((C_KEYWORDS, "C"), (CPP_KEYWORDS, "C++"),
                            (PYTHON_KEYWORDS, "Python")):
        if name in words:
            fail(f"'{name}' is a {language} keyword", f"rename it, e.g. '{name}1'")
    return name


def check_model_name(name, *, file: Optional[str] = API_FILE, line: Optional[int] = None,
                     key: Optional[str] = "name") -> str:
    """Check a model's name (a C prefix): :func:`check_name` without modelgen's
    reserved symbols, and not ``mg`` in any case.

    >>> check_model_name("MG")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    modelgen.errors.ModelError: <api>: name: model name 'MG' is reserved: ...; fix: choose another model name, e.g. 'MG1'
    """
    check_name(name, file=file, line=line, key=key, what="model name",
               modelgen_reserved=False)
    if name.lower() == "mg":
        raise ModelError(f"model name '{name}' is reserved: the generated C names its own "
                         "functions and constants mg_... and MG_..., which the model's "
                         "would clash with", file=file, line=line, key=key,
                         fix=f"choose another model name, e.g. '{name}1'")
    return name


def model_name_for(wanted: str) -> str:
    """A valid model name close to an imported robot's name: sanitized, ``robot_``
    before one that does not start with a letter, ``_robot`` after a keyword, and
    ``robot_`` before a reserved name or prefix.

    >>> model_name_for("2-link arm"), model_name_for("int"), model_name_for("mg_arm")
    ('robot_2_link_arm', 'int_robot', 'robot_mg_arm')
    """
    name = sanitize(wanted)
    if not re.match(r"[A-Za-z]", name):
        name = "robot_" + name
    name = name[:MAX_NAME_LENGTH]
    for candidate in (name, name[:57] + "_robot"):
        try:
            return check_model_name(candidate)
        except ModelError:
            pass
    return "robot_" + name[:57]


def sanitize(name: str) -> str:
    """A foreign name (URDF, MJCF) with every character outside ``[A-Za-z0-9_]``
    replaced by ``_``.

    >>> sanitize("r-arm.joint 1")
    'r_arm_joint_1'
    """
    return re.sub(r"[^A-Za-z0-9_]", "_", name)


def fresh_name(wanted: str, taken: set) -> str:
    """A valid name close to ``wanted`` that is not in ``taken`` (suffix _2, _3...
    on a clash), added to ``taken``: what an importer names a robot's parts."""
    stem = sanitize(wanted)[:56]
    if not re.match(r"[A-Za-z]", stem):
        stem = "L_" + stem
    name, k = stem, 1
    while True:
        try:
            check_name(name)
            ok = (name not in taken and not name.endswith(("_dot", "_ddot"))
                  and f"{name}_dot" not in taken and f"{name}_ddot" not in taken)
        except ModelError:
            ok = False
        if ok:
            taken.add(name)
            return name
        k += 1
        name = f"{stem}_{k}"
