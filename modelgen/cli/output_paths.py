"""Where the commands write, checked before anything is built or run, and what a run's
files say of it beyond their numbers.

An ``-o`` that cannot be written is refused at once, naming the path and the fix:
the operating system would only say so once the build and the run are done, and
their results would be lost.  :func:`describe_run` puts into a result's ``info``
what its NPZ records beside the numbers (the model, the scene, each column's unit).
"""
from __future__ import annotations

import os
from pathlib import Path

from modelgen.errors import ModelgenError

#: the unit of every column of an output of each kind (SI, docs/model-format.md);
#: kinds whose columns differ (a generalized force: N or N m per coordinate, a pose:
#: m and 1, a constraint force: per equation) are given column by column or left ""
OUTPUT_UNITS = {"position": "m", "velocity": "m/s", "orientation": "1",
                "angular_velocity": "rad/s", "energy": "J", "power": "W"}
#: the unit of a generalized force along a coordinate of each unit (its power is in W)
CONJUGATE = {"m": "N", "rad": "N.m"}


def check_output_dir(path, shown=None) -> None:
    """Refuse an output directory that cannot be one before anything is built or run
    (``shown``: the -o path it is the folder of, if not itself): the nearest existing
    folder on its way must be a directory this process may write into."""
    fix = "give a directory (it is created if missing)" if shown is None else \
        "give a file in a directory (missing directories are created)"
    for parent in (Path(path), *Path(path).parents):
        if parent.exists():
            if not parent.is_dir():
                raise ModelgenError(f"-o {shown or path}: {parent} is a file, not a directory; "
                                    f"fix: {fix}")
            if not os.access(parent, os.W_OK | os.X_OK):
                raise ModelgenError(f"-o {shown or path}: the directory {parent} is not "
                                    f"writable; fix: give -o a directory you can write to, "
                                    f"or change the permissions of {parent}")
            break


def check_output_file(path, example: str) -> None:
    """Refuse an output file that cannot be one (a directory, or under a file, or in a
    directory that cannot be written) before anything is built or run."""
    path = Path(path)
    if path.is_dir():
        raise ModelgenError(f"-o {path}: {path} is a directory, not a file; fix: give a file "
                            f"name, e.g. -o {path / example}")
    check_output_dir(path.parent, shown=path)


def column_units(result, outputs=(), units=None) -> list:
    """The unit of each column of ``result.columns()``: t in s; a state's from
    ``units`` (:attr:`CompiledModel.units`: the model's, a speed's per second);
    outputs by kind (``outputs``: the OutputSpec of each), assuming SI as
    modelgen's examples do (it does not know a model's unit of length), a
    generalized force by its coordinate's unit (N along m, N.m along rad);
    energies and work in J; "" where unknown."""
    units = dict(units or {})
    kinds = {o.name: o.kind for o in outputs}
    out = []
    for column in result.columns():
        head = column.split(".")[0].split("[")[0]
        if column == "t":
            out.append("s")
        elif column in result.state_names:
            out.append(units.get(column, ""))
        elif column in ("kinetic", "potential", "total") or column.startswith("work."):
            out.append("J")
        elif kinds.get(head) == "generalized_force":   # conjugate to its coordinate
            coordinate = column[len(head) + 1:]
            out.append(CONJUGATE.get(units.get(coordinate), ""))
        elif kinds.get(head) == "pose":
            out.append("m" if column.endswith(",3]") and not column.endswith("[3,3]") else "1")
        else:
            out.append(OUTPUT_UNITS.get(kinds.get(head), ""))
    return out


def describe_run(result, *, model: str, scene=None, outputs=(), units=None) -> None:
    """Record in ``result.info`` what the run's NPZ carries beside the numbers: the
    model's and scene's names and the unit of every column (see :func:`column_units`)."""
    result.info.update(model=model, units=column_units(result, outputs, units))
    if scene is not None:
        result.info["scene"] = scene
