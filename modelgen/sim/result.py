"""The one result type of every simulation: scipy's ``OdeResult`` layout, plus names.

Every way to integrate (``CompiledModel.simulate`` with any method, scenes,
the CLI) returns a :class:`Result`:

* ``t`` (n_times,), ``y`` (n_states, n_times) as in ``solve_ivp``;
* ``sol`` (a callable ``sol(t) -> y`` when ``dense_output=True``, else None),
  ``t_events``, ``y_events``;
* ``status`` (0 reached the end, 1 a terminal event, negative a failure; see
  :data:`modelgen.sim.integrate.STATUS`), ``message``, ``success``;
* statistics ``nfev``, ``njev``, ``nlu``, ``naccept``, ``nreject``, ``nnewton``;
* names: ``res["q1"]`` is a state's time series, ``res["elbow"]`` a recorded
  output (n_times, columns).

A failed run keeps everything computed up to the failure; ``t_fail`` is the
time of the failure and ``message`` says why.

>>> res = cm.simulate([1.0, 0.0, 0.0, 0.0], (0, 10), t_eval=np.linspace(0, 10, 101))  # doctest: +SKIP
>>> res["q1"].shape, res.success, res.to_csv("dp.csv")                                   # doctest: +SKIP
"""
from __future__ import annotations

import contextlib
import errno
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, NamedTuple, Optional

import numpy as np

#: bytes of CSV text per value, on average (repr of a double and a comma): for estimates
CSV_BYTES_PER_VALUE = 20
#: rows of CSV formatted per write (a Ctrl-C between two writes stops at once)
CSV_BLOCK = 4096


def output_bytes(samples: float, columns: int, runs: float = 1, *, csv: bool = False) -> float:
    """The size in bytes of a run's (or a sweep's) results: samples x columns x runs
    doubles, plus the CSV text when ``csv``; a float, so huge counts never overflow.

    >>> output_bytes(1001, 5) / 1e6, output_bytes(1001, 5, csv=True) / 1e6
    (0.04004, 0.14014)
    """
    values = float(samples) * float(columns) * float(runs)
    return values * 8 + (values * CSV_BYTES_PER_VALUE if csv else 0.0)


@contextlib.contextmanager
def replacing(path):
    """Write a file under a temporary name beside ``path`` and rename it to ``path``
    only when the writing succeeded: an interrupt, a full disk or any error never
    leaves a cut file under the final name (the temporary one is removed).  Yields
    the temporary path (it keeps ``path``'s suffix, as ``np.savez`` wants).

    >>> with replacing(tmp / "a.txt") as part:                    # doctest: +SKIP
    ...     part.write_text("done")
    """
    path = Path(path)
    part = path.with_name(f".{path.stem}.part-{os.getpid()}{path.suffix}")
    try:
        yield part
        os.replace(part, path)
    except OSError as exc:
        with contextlib.suppress(OSError):
            part.unlink()
        if exc.errno == errno.ENOSPC:
            raise OSError(exc.errno, "No space left on device (the disk is full) while "
                                     "writing", str(path)) from exc
        if exc.filename is None or Path(exc.filename) == part:
            raise OSError(exc.errno, exc.strerror or str(exc), str(path)) from exc
        raise
    except BaseException:           # KeyboardInterrupt included: no cut file stays behind
        with contextlib.suppress(OSError):
            part.unlink()
        raise


def csv_rows(block: np.ndarray) -> str:
    """The CSV lines (``\\r\\n`` ended) of a 2-D float array, every value as its
    ``repr``: the shortest text that reads back as the same double.

    Formatting the floats is nearly all of the cost, so each distinct column is
    formatted once: a column equal bit for bit to an earlier one (a pose repeats
    its rotation matrix, an orientation's entries repeat) reuses its strings, and a
    constant one (the z components of a planar model) is one string.

    >>> csv_rows(np.array([[0.1, 0.0, 0.1], [1e-300, 0.0, 1e-300]]))
    '0.1,0.0,0.1\\r\\n1e-300,0.0,1e-300\\r\\n'
    """
    block = np.asarray(block, dtype=float)
    bits = np.ascontiguousarray(block.T).view(np.int64)     # -0.0 and NaNs kept apart
    done, texts = {}, []
    for j, column in enumerate(bits):
        key = column.tobytes()
        text = done.get(key)
        if text is None:
            values = block[:, j].tolist()
            if len(values) and (column == column[0]).all():
                text = [repr(values[0])] * len(values)
            else:
                text = list(map(repr, values))
            done[key] = text
        texts.append(text)
    return "".join(f"{line}\r\n" for line in map(",".join, zip(*texts)))


class EnergyChange(NamedTuple):
    """The change of the total energy over a run, and the scale it is measured against.

    ``scale`` is the largest ``|T| + |V|`` of the run, not E(0): a body released
    from rest where its potential is zero starts with E(0) = 0 exactly, and a
    change divided by it would be noise over zero.  ``relative`` (``change /
    scale``, at most 2 in size) is None when the scale is 0: the energies stayed
    exactly zero, and only ``change`` in J means anything.
    """
    change: float        # E(end) - E(0) [J]
    scale: float         # max over the run of |T| + |V| [J]
    relative: Optional[float]

    def describe(self, conservative: bool = False) -> str:
        """One line: the relative change (or error, for a conservative run) and its scale."""
        label = "energy error" if conservative else "energy change"
        if not np.isfinite(self.change):
            return f"{label} {self.change} J (the energies overflowed)"
        if self.relative is None:
            return f"{label} {self.change:.3e} J (the energies stayed zero)"
        return (f"relative {label} {self.relative:.3e} (against the largest |T| + |V| of "
                f"the run, {self.scale:.6g} J)")


@dataclass
class Result:
    """A trajectory in scipy's layout (see the module docstring)."""
    t: np.ndarray
    y: np.ndarray
    state_names: tuple = ()
    #: how many of ``state_names`` are coordinates (the rest are speeds); None:
    #: half of them (a model without ball or free joints)
    n_coordinates: Optional[int] = None
    status: int = 0
    message: str = "The solver successfully reached the end of the integration interval."
    method: str = ""
    sol: Optional[Callable] = None
    t_events: Optional[list] = None
    y_events: Optional[list] = None
    t_fail: Optional[float] = None
    nfev: int = 0
    njev: int = 0
    nlu: int = 0
    naccept: int = 0
    nreject: int = 0
    nnewton: int = 0
    #: recorded outputs: name -> (n_times, columns), and their column names
    outputs: dict = field(default_factory=dict)
    output_columns: dict = field(default_factory=dict)
    #: kinetic and potential energy at each time (n_times, 2), when recorded
    energy: Optional[np.ndarray] = None
    #: work of each effect outside the energy (damping, friction, actions): name ->
    #: W_k(t) = integral of its power (n_times,) [J], recorded by scenes; the energy
    #: balance E(t) - E(0) - sum W_k(t) is in ``info["energy_balance"]``
    work: dict = field(default_factory=dict)
    #: what else the run knows (scene name, parameters...)
    info: dict = field(default_factory=dict)

    @property
    def success(self) -> bool:
        """True when the run reached the end or a terminal event (``status >= 0``)."""
        return self.status >= 0

    # -- access by name -----------------------------------------------------------
    def __getitem__(self, name: str):
        """A state's time series (``res["q1"]``, ``res["q1_dot"]``), a recorded output
        (``res["elbow"]``, shape (n_times, columns)), a field (``res["nfev"]``), as
        scipy's OdeResult allows, or else one column of :meth:`table` by its CSV
        name (``res["elbow.x"]``, ``res["kinetic"]``, ``res["work.damping"]``:
        shape (n_times,)).  Names of states and outputs come first."""
        if name in self.state_names:
            return self.y[self.state_names.index(name)]
        if name in self.outputs:
            return self.outputs[name]
        if name in _FIELDS:
            return getattr(self, name)
        column = self._column(name)
        if column is not None:
            return column
        raise KeyError(f"{name!r} is neither a state, a recorded output, a field nor a "
                       f"column of the table; states and outputs: "
                       f"{', '.join(self.names()) or 'none'}")

    def _column(self, name):
        """The column of :meth:`table` whose CSV name is ``name`` (an output's column, an
        energy or a work), or None."""
        for output, values in self.outputs.items():
            columns = list(self.output_columns.get(output, ()))
            if name in columns:
                return np.asarray(values).reshape(len(self.t), -1)[:, columns.index(name)]
        if self.energy is not None and name in ("kinetic", "potential", "total"):
            return (self.energy.sum(axis=1) if name == "total"
                    else self.energy[:, ("kinetic", "potential").index(name)])
        if name.startswith("work.") and name[5:] in self.work:
            return np.asarray(self.work[name[5:]])
        return None

    def __contains__(self, name) -> bool:
        return (name in self.state_names or name in self.outputs or name in _FIELDS
                or self._column(name) is not None)

    def names(self) -> list:
        """The states, then the recorded outputs."""
        return list(self.state_names) + list(self.outputs)

    def keys(self) -> list:
        """Everything ``res[...]`` accepts: states, outputs, the fields, then the other
        columns of :meth:`table` (an output's, the energies, the works)."""
        named = self.names() + [f for f in _FIELDS if f not in self.names()]
        return named + [c for c in self.columns() if c not in named]

    def energy_change(self) -> EnergyChange:
        """E(end) - E(0) of a run with recorded energies, against the largest
        ``|T| + |V|`` of the run (see :class:`EnergyChange`).

        >>> T_V = np.array([[0.0, 0.0], [1.0, -1.0], [2.0, -3.0]])   # from rest, E(0) = 0
        >>> Result(np.arange(3.0), np.zeros((2, 3)), energy=T_V).energy_change()
        EnergyChange(change=-1.0, scale=5.0, relative=-0.2)
        """
        if self.energy is None or not len(self.energy):
            raise ValueError("this result has no recorded energies")
        energy = np.asarray(self.energy, dtype=float)
        with np.errstate(over="ignore", invalid="ignore"):   # an overflowed run: inf or nan
            total = energy.sum(axis=1)
            change = float(total[-1] - total[0])
            sizes = np.abs(energy).sum(axis=1)
        scale = float(np.max(sizes[np.isfinite(sizes)], initial=0.0))
        return EnergyChange(change, scale, change / scale if scale > 0 else None)

    # -- tables ---------------------------------------------------------------------
    def columns(self) -> list:
        """Column names of :meth:`table`: t, the states, the outputs' columns, energies."""
        names = ["t", *self.state_names]
        for name in self.outputs:
            names += list(self.output_columns.get(name, [name]))
        if self.energy is not None:
            names += ["kinetic", "potential", "total"]
        names += [f"work.{name}" for name in self.work]
        return names

    def table(self) -> np.ndarray:
        """One row per time: the columns of :meth:`columns`."""
        parts = [self.t[:, None], self.y.T]
        parts += [np.asarray(v).reshape(len(self.t), -1) for v in self.outputs.values()]
        if self.energy is not None:
            parts += [self.energy, self.energy.sum(axis=1, keepdims=True)]
        parts += [np.asarray(w).reshape(-1, 1) for w in self.work.values()]
        return np.hstack(parts)

    def to_csv(self, path) -> Path:
        """Write :meth:`table` with a header line; floats round-trip exactly.  The file
        appears under ``path`` only once it is complete (see :func:`replacing`)."""
        import csv      # here: a load that writes no CSV does not import it
        path = Path(path)
        table = np.asarray(self.table(), dtype=float)
        # blocks of rows let a second Ctrl-C stop it at once
        with replacing(path) as part, part.open("w", newline="") as fh:
            csv.writer(fh).writerow(self.columns())
            for start in range(0, len(table), CSV_BLOCK):
                fh.write(csv_rows(table[start:start + CSV_BLOCK]))
        return path

    def to_npz(self, path) -> Path:
        """t, y, the state names, every output (``output:<name>``), the energies, the
        work of each effect (``work:<name>``), ``status``, ``message`` and ``partial``
        (True when the run did not reach its end: interrupted or failed), ``t_fail``
        (NaN unless it failed), ``t_reached`` (where it stopped: ``t_fail``, else the
        last sample), ``method``, ``columns`` (the CSV's column names, in its order),
        and when ``info`` has them ``model``, ``scene`` and ``units`` (one per column,
        "" where unknown; the command line records them).  Only numbers and text:
        ``np.load(path, allow_pickle=False)`` reads it.  The file appears under
        ``path`` only once it is complete (see :func:`replacing`)."""
        path = Path(path)
        arrays = {"t": self.t, "y": self.y, "x": self.y.T,
                  **{f"output:{k}": v for k, v in self.outputs.items()}}
        if self.energy is not None:
            arrays["energy"] = self.energy
        arrays.update({f"work:{k}": v for k, v in self.work.items()})
        columns = self.columns()
        meta = {key: str(self.info[key]) for key in ("model", "scene") if key in self.info}
        if len(self.info.get("units", ())) == len(columns):
            meta["units"] = np.array(self.info["units"], dtype=str)
        t_fail = np.nan if self.t_fail is None else float(self.t_fail)
        last = float(self.t[-1]) if len(self.t) else np.nan
        reached = last if self.t_fail is None else t_fail
        with replacing(path) as part:
            np.savez(part, status=self.status, message=self.message, partial=not self.success,
                     t_fail=t_fail, t_reached=reached, method=str(self.method),
                     state_names=np.array(self.state_names, dtype=str),
                     columns=np.array(columns, dtype=str), **meta, **arrays)
        return path

    def to_dataframe(self):
        """A pandas DataFrame indexed by t with the columns of :meth:`columns` (needs pandas)."""
        try:
            import pandas
        except ImportError as exc:   # optional dependency
            raise ImportError("Result.to_dataframe needs pandas: pip install pandas") from exc
        columns = self.columns()
        return pandas.DataFrame(self.table()[:, 1:], index=pandas.Index(self.t, name="t"),
                                columns=columns[1:])

    def plot(self, path=None, *, title: str = "", conservative: Optional[bool] = None):
        """A matplotlib Figure of the states, the outputs and the energy.

        Never touches pyplot's global state or backend: the figure is a
        ``matplotlib.figure.Figure``; with ``path`` it is also saved there.
        """
        from modelgen.sim.plots import result_figure
        fig = result_figure(self, title=title, conservative=conservative)
        if path is not None:
            with replacing(path) as part:
                fig.savefig(part, dpi=110)
        return fig

    def __repr__(self) -> str:
        """One line per field, as scipy prints an OdeResult (arrays by their shape)."""
        shown = [f for f in _FIELDS if (f != "energy" or self.energy is not None)
                 and (f != "work" or self.work)]
        shown += ["state_names"] + (["outputs"] if self.outputs else [])
        width = max(map(len, shown)) + 1
        lines = []
        for name in shown:
            value = getattr(self, name)
            if isinstance(value, np.ndarray):
                text = f"array{value.shape}"
            elif name in ("outputs", "work"):
                text = "{" + ", ".join(f"{k!r}: array{np.shape(v)}" for k, v in value.items()) + "}"
            else:
                text = repr(value)
            lines.append(f"{name.rjust(width)}: {text}")
        return "\n".join(lines)


class DenseOutput:
    """``sol(t)`` of a run: on each accepted step, the polynomial through the method's
    own dense output sampled at 8 Chebyshev-Lobatto points of the step.

    Degree 7 reproduces the continuous extensions of every method exactly
    (dop853's is of degree 7, dopri5's 4, rodas's and the Hermite of the
    fixed-step methods 3), so ``sol`` is as accurate as ``t_eval`` sampling.
    ``sol(t)`` returns shape (n_states,) for a scalar t, else (n_states, len(t)),
    NaN at times outside the steps the run took (scipy's ``OdeSolution``
    extrapolates the end polynomials there, which past a failure is garbage).
    The quaternions of ball and free joints (``quaternions``: their state
    indices) are normalised, as the integrators normalise their samples.
    """

    #: interpolation nodes on [0, 1] and their barycentric weights
    NODES = (1.0 - np.cos(np.pi * np.arange(8) / 7)) / 2
    WEIGHTS = np.array([0.5, -1, 1, -1, 1, -1, 1, -0.5])

    def __init__(self, t_steps: np.ndarray, values: np.ndarray, quaternions=()):
        self.quaternions = tuple(tuple(q) for q in quaternions)
        self.t = np.asarray(t_steps, dtype=float)        # (n_steps + 1,)
        self.values = np.asarray(values, dtype=float)    # (n_steps, 8, n_states)
        self.t_min, self.t_max = float(self.t[0]), float(self.t[-1])

    def __call__(self, t):
        ts = np.atleast_1d(np.asarray(t, dtype=float))
        k = np.clip(np.searchsorted(self.t, ts, side="right") - 1, 0, len(self.t) - 2)
        h = self.t[k + 1] - self.t[k]
        s = (ts - self.t[k]) / h
        diff = s[:, None] - self.NODES[None, :]                  # (n_t, 8)
        exact = diff == 0.0
        with np.errstate(divide="ignore", invalid="ignore"):   # the NaN ones: see below
            c = self.WEIGHTS[None, :] / diff
            c = np.where(exact.any(axis=1, keepdims=True), exact.astype(float), c)
            c /= c.sum(axis=1, keepdims=True)
        out = np.einsum("tj,tjn->nt", c, self.values[k])
        for quat in self.quaternions:
            out[list(quat)] /= np.linalg.norm(out[list(quat)], axis=0)
        slack = 4 * np.finfo(float).eps * max(abs(self.t_min), abs(self.t_max))
        out[:, (ts < self.t_min - slack) | (ts > self.t_max + slack)] = np.nan
        return out[:, 0] if np.ndim(t) == 0 else out


#: the fields of a result, as scipy's OdeResult has them (plus modelgen's own)
_FIELDS = (*(name for name in Result.__dataclass_fields__
             if name not in ("state_names", "outputs", "output_columns", "info")), "success")


def make_result(**fields: Any) -> Result:
    """A :class:`Result` from keyword fields (unknown keys go to ``info``)."""
    known = Result.__dataclass_fields__
    fields.pop("success", None)          # derived from status
    info = {k: v for k, v in fields.items() if k not in known}
    kwargs = {k: v for k, v in fields.items() if k in known}
    kwargs.setdefault("info", {}).update(info)
    return Result(**kwargs)
