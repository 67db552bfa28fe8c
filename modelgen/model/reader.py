"""The YAML reader: untrusted text -> plain data and a line table.

Input: the text of a model or scene file (and the file's name, for errors).
Output: ``(data, lines)``: the document as plain dicts, lists, strings,
numbers, booleans and None, and ``{dotted key: 1-based line}``
(``bases.B1.parent``, ``points.P1.coordinates[0]``) for every key and item,
so later errors can point at a line.  A YAML safe loader that also refuses
aliases (so merge keys), explicit tags, duplicate keys, non-string keys and
values of other types (e.g. dates); each refusal, and every YAML syntax error,
is a :class:`~modelgen.errors.ModelError` naming the file and line.
"""
from __future__ import annotations

import math
import os
import re
import unicodedata
from typing import Optional

import yaml

from modelgen.errors import ModelError

__all__ = ["compose", "read_text"]


class _Loader(yaml.SafeLoader):
    """SafeLoader that refuses aliases (no billion-laughs expansion)."""

    def compose_node(self, parent, index):
        if self.check_event(yaml.AliasEvent):
            event = self.peek_event()
            raise _YamlProblem(f"YAML alias '*{event.anchor}' is not supported (aliases are "
                               "refused)", event.start_mark.line + 1,
                               "write the value out in full")
        return super().compose_node(parent, index)


class _YamlProblem(Exception):
    def __init__(self, problem: str, line: Optional[int], fix: str, key: Optional[str] = None):
        super().__init__(problem)
        self.problem, self.line, self.fix, self.key = problem, line, fix, key


#: integers beyond this cannot become doubles (float() would overflow)
MAX_INTEGER = 10 ** 308
#: deepest nesting of YAML collections accepted (models need 4 or 5 levels)
MAX_NESTING = 64

_SCALAR_TAGS = {"tag:yaml.org,2002:" + t for t in ("str", "int", "float", "bool", "null")}
_MAP_TAG = "tag:yaml.org,2002:map"
_SEQ_TAG = "tag:yaml.org,2002:seq"


def _plain(node, path: str, lines: dict, loader: _Loader):
    """Convert a composed YAML node to plain Python data, recording lines by key."""
    line = node.start_mark.line + 1
    if path not in lines:
        lines[path] = line
    if path.count(".") + path.count("[") >= MAX_NESTING:
        raise _YamlProblem(f"YAML nested more than {MAX_NESTING} levels deep", line,
                           "flatten the document: models need a few levels only", path or None)
    if isinstance(node, yaml.MappingNode):
        if node.tag != _MAP_TAG:
            raise _YamlProblem(f"unsupported YAML tag '{node.tag}'", line,
                               "remove the tag", path or None)
        result: dict = {}
        first_line: dict = {}
        for key_node, value_node in node.value:
            key_line = key_node.start_mark.line + 1
            if not isinstance(key_node, yaml.ScalarNode) or key_node.tag != "tag:yaml.org,2002:str":
                if key_node.tag == "tag:yaml.org,2002:merge":
                    raise _YamlProblem("YAML merge keys '<<' are not supported", key_line,
                                       "write the keys out in full", path or None)
                shown = getattr(key_node, "value", "?")
                shown = shown if isinstance(shown, str) else "a collection"
                raise _YamlProblem(f"key {shown!r} is not a name (YAML reads it as "
                                   f"{key_node.tag.rsplit(':', 1)[-1]})", key_line,
                                   f"quote the key: \"{shown}\"" if isinstance(shown, str)
                                   else "use a name as the key", path or None)
            key = key_node.value
            child = f"{path}.{key}" if path else key
            if key in result:
                raise _YamlProblem(f"duplicate key '{key}' (first at line {first_line[key]})",
                                   key_line, "remove or rename one of them", child)
            first_line[key] = key_line
            lines[child] = key_line
            result[key] = _plain(value_node, child, lines, loader)
        return result
    if isinstance(node, yaml.SequenceNode):
        if node.tag != _SEQ_TAG:
            raise _YamlProblem(f"unsupported YAML tag '{node.tag}'", line, "remove the tag",
                               path or None)
        return [_plain(item, f"{path}[{i}]", lines, loader)
                for i, item in enumerate(node.value)]
    if node.tag not in _SCALAR_TAGS:
        implicit = loader.resolve(yaml.ScalarNode, node.value, (True, False))
        if node.tag == implicit:
            raise _YamlProblem(f"unsupported YAML value {node.value!r} (read as "
                               f"{node.tag.rsplit(':', 1)[-1]})", line, "quote the value",
                               path or None)
        raise _YamlProblem(f"unsupported YAML tag '{node.tag}'", line, "remove the tag",
                           path or None)
    try:
        value = loader.construct_object(node, deep=True)
    except (ValueError, KeyError, TypeError, OverflowError, yaml.YAMLError) as exc:
        raise _YamlProblem(f"cannot read the value {node.value[:40]!r} as "
                           f"{node.tag.rsplit(':', 1)[-1]} ({type(exc).__name__})", line,
                           "write a plain number, true/false, or a quoted string",
                           path or None) from None
    if isinstance(value, int) and not isinstance(value, bool) and abs(value) > MAX_INTEGER:
        raise _YamlProblem(f"the integer {node.value[:20]}... is beyond the range of a double "
                           f"(more than {len(str(MAX_INTEGER))} digits)", line,
                           "write a number below 1e308 (as a float: 1.5e300)", path or None)
    if isinstance(value, float) and (math.isinf(value) or value == 0) \
            and re.search(r"[1-9]", node.value.lower().partition("e")[0]):
        # 1.0e400 or 1.0e-400, which float() makes inf or 0 (.inf is inf as written)
        problem, fix = ("overflows a double (its magnitude is above 1.8e308)",
                        "write a number of magnitude at most 1.7e308") if value else \
            ("is too small for a double (it would be 0)",
             "use a magnitude of at least 5e-324, or 0")
        raise _YamlProblem(f"the number {node.value[:40]} {problem}", line, fix, path or None)
    return value


def compose(text: str, file: str) -> tuple:
    """Parse YAML text into plain data and a {dotted key: line} table.

    >>> compose("a: {b: [1, x]}", "<doc>")
    ({'a': {'b': [1, 'x']}}, {'a': 1, 'a.b': 1, 'a.b[0]': 1, 'a.b[1]': 1})
    """
    try:
        loader = _Loader(text)       # the reader checks every character here
    except yaml.reader.ReaderError as exc:
        line = text.count("\n", 0, exc.position) + 1 if isinstance(text, str) else None
        code = exc.character if isinstance(exc.character, int) else ord(exc.character)
        raise ModelError(f"the file contains the character U+{code:04X} "
                         f"({unicodedata.name(chr(code), 'a control character or non-character')}), which "
                         "YAML does not allow", file=file, line=line,
                         fix="remove it (a pasted terminal colour code or a binary file?)") from None
    try:
        try:
            node = loader.get_single_node()
            if node is None:
                return None, {}
            lines: dict = {}
            data = _plain(node, "", lines, loader)
            lines.pop("", None)
            return data, lines
        finally:
            loader.dispose()
    except _YamlProblem as exc:
        raise ModelError(exc.problem, file=file, line=exc.line, key=exc.key,
                         fix=exc.fix) from None
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        problem = f"invalid YAML: {exc.problem}"
        if exc.context:
            problem += f" ({exc.context})"
        raise ModelError(problem, file=file, line=mark.line + 1 if mark else None,
                         fix="correct the YAML syntax near this line") from None
    except yaml.YAMLError as exc:
        raise ModelError(f"invalid YAML: {exc}", file=file,
                         fix="correct the YAML syntax") from None
    except RecursionError:
        raise ModelError("YAML nested too deeply to read", file=file,
                         fix=f"flatten the document (at most {MAX_NESTING} levels)") from None


def read_text(path, what: str = "model") -> tuple:
    """``(file name, text)`` of a UTF-8 file, or a ModelError naming the file."""
    file = os.fspath(path)
    try:
        with open(file, encoding="utf-8") as handle:
            return file, handle.read()
    except OSError as exc:
        raise ModelError(f"cannot read the {what} file: {exc.strerror or exc}", file=file,
                         fix="check the path") from None
    except UnicodeDecodeError as exc:
        line = exc.object[:exc.start].count(b"\n") + 1
        raise ModelError(f"the {what} file is not UTF-8 text ({exc.reason} at byte "
                         f"{exc.start})", file=file, line=line,
                         fix="save the file as UTF-8") from None
