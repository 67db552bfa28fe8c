"""Section readers: the plain data of a model file -> calls on a ModelBuilder.

Input: ``(data, lines)`` from :func:`modelgen.model.reader.compose` (or the
``add_parameters`` / ``add_effects`` sections of a scene file).
Output: a :class:`~modelgen.model.builder.ModelBuilder` holding every entry,
validated but not yet resolved (call ``build()`` for the ModelSpec).  One
reader per top-level key, in :data:`~modelgen.model.schema.TOP_LEVEL_KEYS`
order; the shapes of sections and entries (a mapping of names to mappings,
known keys, required keys) are checked here, the values by the builder.
"""
from __future__ import annotations

from modelgen.errors import ModelError
from modelgen.model.builder import ModelBuilder
from modelgen.model.messages import closest, describe, join_and
from modelgen.model.reader import compose
from modelgen.model.schema import (ENTRY_KEYS, REQUIRED_KEYS, SECTION_EXAMPLES, SECTION_KIND,
                                   TOP_LEVEL_KEYS)
from modelgen.model.spec import EFFECT_KINDS

__all__ = ["check_top_level", "check_entry_keys", "mapping_entries", "load_parameters",
           "load_effects", "builder_from_data", "builder_from_text"]


def check_entry_keys(ctx: ModelBuilder, entry: dict, section: str, key: str) -> None:
    """An entry of ``section`` has only known keys and every required one."""
    valid = ENTRY_KEYS[section]
    for field in entry:
        if field not in valid:
            close = closest(field, valid)
            fix = f"did you mean '{close}'? " if close else ""
            fix += "valid keys: " + ", ".join(valid)
            raise ctx.error(f"unknown key '{field}'", f"{key}.{field}", fix)
    for field in REQUIRED_KEYS[section]:
        if field not in entry:
            kind = SECTION_KIND[section]
            raise ctx.error(f"missing required key '{field}'", key,
                            f"add '{field}'; a {kind} needs " + join_and(REQUIRED_KEYS[section]))


def mapping_entries(ctx: ModelBuilder, value, section: str, key: str, kind: str):
    """``(name, entry, key)`` of a mapping section whose entries are mappings."""
    if value is None:
        return
    example = SECTION_EXAMPLES[section]
    if not isinstance(value, dict):
        raise ctx.error(f"expected a mapping of {kind} names to definitions but got "
                        f"{describe(value)}", key,
                        f"write one entry per line, e.g. '{example}'")
    for name, entry in value.items():
        entry_key = f"{key}.{name}"
        if not isinstance(entry, dict):
            raise ctx.error(f"expected a mapping but got {describe(entry)}", entry_key,
                            f"write it like '{example}'")
        yield name, entry, entry_key


def load_effects(ctx: ModelBuilder, value, key: str = "effects") -> None:
    """Add the entries of an ``effects:`` mapping (``key``: its dotted key)."""
    for name, entry, entry_key in mapping_entries(ctx, value, "effects", key, "effect"):
        if "type" not in entry:
            raise ctx.error("missing required key 'type'", entry_key,
                            "add 'type: <effect type>', one of " + ", ".join(EFFECT_KINDS))
        fields = {k: v for k, v in entry.items() if k != "type"}
        ctx.add_effect(name, entry["type"], fields, entry_key)


def load_parameters(ctx: ModelBuilder, value, key: str = "parameters") -> None:
    """Add the entries of a ``parameters:`` mapping (``key``: its dotted key)."""
    if value is None:
        return
    if not isinstance(value, dict):
        raise ctx.error(f"expected a mapping of parameter names to defaults but got "
                        f"{describe(value)}", key, f"write {key}: {{m: 1.0, g: 9.81}}")
    for name, default in value.items():
        ctx.add_parameter(name, default, f"{key}.{name}")


def check_top_level(data, ctx: ModelBuilder, what: str, keys, start: str,
                    empty: str = "") -> None:
    """A parsed file is a non-empty mapping whose keys are all in ``keys``.

    Shared by model and scene files; ``start`` says how such a file begins, and
    ``empty`` what else an empty one may have been meant as.
    """
    if data is None:
        raise ModelError(f"the {what} file is empty", file=ctx.file, line=1, fix=start + empty)
    if not isinstance(data, dict):
        raise ModelError(f"expected a mapping of {what} keys but got {describe(data)}",
                         file=ctx.file, line=1, fix=f"{start} and use the keys " + ", ".join(keys))
    for key in data:
        if key not in keys:
            close = closest(key, keys)
            fix = f"did you mean '{close}'? " if close else ""
            raise ctx.error(f"unknown key '{key}'", key, fix + "valid keys: " + ", ".join(keys))


def builder_from_data(data, lines: dict, file: str) -> ModelBuilder:
    """The validated declarations of a parsed model file, not yet resolved."""
    ctx = ModelBuilder(file, lines)
    check_top_level(data, ctx, "model", TOP_LEVEL_KEYS, "start with 'name: <model name>'",
                    " (or, for a scene, with 'scene: <name>' and 'model: <model file>')")
    if "name" not in data:
        raise ModelError("missing required key 'name'", file=file, line=1,
                         fix="add 'name: <model name>' (a C identifier) at the top level")
    ctx.set_name(data["name"])
    ctx.set_description(data.get("description"))
    ctx.set_physical_inertia(data.get("physical_inertia"))

    def names_list(section: str):
        value = data.get(section)
        if value is None:
            return []
        if not isinstance(value, list):
            example = "q1, q2" if section == "coordinates" else "T1, T2"
            raise ctx.error(f"expected a list of names but got {describe(value)}", section,
                            f"write {section}: [{example}]")
        return value

    for i, name in enumerate(names_list("coordinates")):
        ctx.add_coordinate(name, f"coordinates[{i}]")
    load_parameters(ctx, data.get("parameters"))
    for i, name in enumerate(names_list("inputs")):
        ctx.add_input(name, f"inputs[{i}]")

    def entries(section: str):
        for name, entry, key in mapping_entries(ctx, data.get(section), section, section,
                                                SECTION_KIND[section]):
            check_entry_keys(ctx, entry, section, key)
            yield name, entry, key

    # joints first: they declare their coordinates, bases and points, which the
    # other sections may name (and whose coordinates no expression may use)
    for name, e, key in entries("joints"):
        ctx.add_joint(name, e["type"], e["parent"], e["base"], e.get("from"), e.get("point"),
                      key)
    for name, e, key in entries("bases"):
        ctx.add_base(name, e["parent"], e["axis"], e["angle"], key)
    for name, e, key in entries("points"):
        ctx.add_point(name, e.get("from"), e.get("base"), e.get("frame"),
                      e["coordinates"], key)
    for name, e, key in entries("frames"):
        ctx.add_frame(name, e["point"], e["base"], key)
    for name, e, key in entries("bodies"):
        ctx.add_body(name, e["mass"], e["G"], e["base"], e.get("inertia"), key)
    if "gravity" in data:
        ctx.set_gravity(data["gravity"])
    ctx.set_units(data.get("units"))
    for name, e, key in entries("actions"):
        ctx.add_action(name, e["body"], e.get("point"), e.get("base"), e.get("frame"),
                       e.get("torque"), e.get("force"), e.get("vector"), key)
    load_effects(ctx, data.get("effects"))
    ctx.set_armature(data.get("armature"))
    for name, e, key in entries("constraints"):
        ctx.add_constraint(name, e["type"], {k: v for k, v in e.items() if k != "type"}, key)
    if "dependent" in data:
        ctx.set_dependent(data["dependent"])
    return ctx


def builder_from_text(text: str, source: str) -> ModelBuilder:
    if not isinstance(text, str):
        raise ModelError(f"expected YAML text but got {describe(text)}", file=source,
                         fix="pass the file's text, or use load_model(path)")
    data, lines = compose(text, source)
    return builder_from_data(data, lines, source)
