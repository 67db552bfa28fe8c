"""The time rules of a scene: its span, sample interval and fixed step, checked alike
for the scene file and for the settings a run overrides.

Input: the start and end times, the sample interval, whether the method takes a
fixed step, the step, and a :class:`Spelling` (how the caller writes each
setting: the scene file's keys, the command line's flags, Python keywords).
Output: None, or the first broken rule as a :class:`Problem` (the setting to
blame, what is wrong, the fix in the caller's words).  The scene reader
(``scene.py``) turns a problem into a ModelError at the key's line, a run's
overrides (:func:`modelgen.sim.scene.with_settings`) into an ArgumentValueError.
Plain Python only: a cached scene run imports this without sympy or YAML.
"""
from __future__ import annotations

import math
from typing import NamedTuple, Optional

__all__ = ["MAX_SCENE_STEPS", "REL_TOL", "Problem", "Spelling", "FILE_SPELLING",
           "timing_problem"]

#: the most fixed steps a scene may take over its span: beyond it a run takes hours
#: (and a denormal step's count overflows every counter); an adaptive method, or a
#: model run from Python with max_steps, is the way past it
MAX_SCENE_STEPS = 1e9
#: steps past this overflow the C integrators' step counter (a 64-bit long)
_COUNTER_LIMIT = 2.0 ** 63
#: how far the sample interval may be from a whole number of steps, relative to it
REL_TOL = 1e-9


class Problem(NamedTuple):
    """A broken time rule: ``key`` is the setting to blame, as the scene file names it
    (``time.sample``, ``integrator.step``)."""
    key: str
    problem: str
    fix: str


class Spelling(NamedTuple):
    """How the caller writes a setting in a message: ``names`` maps a scene file key to
    the caller's name for it (missing: the key itself), and ``assign`` is the
    format of a setting with a value (``{name}``, ``{field}``: the key's last part,
    ``{value}``)."""
    names: dict
    assign: str

    def name(self, key: str) -> str:
        return self.names.get(key, key)

    def write(self, key: str, value) -> str:
        shown = value if isinstance(value, str) else repr(value)
        return self.assign.format(name=self.name(key), field=key.rsplit(".", 1)[-1],
                                  value=shown)


#: the scene file's own words: ``integrator.step``, ``step: 0.001``
FILE_SPELLING = Spelling({}, "{field}: {value}")


def _short(value: float) -> float:
    """``value`` rounded to 12 significant digits, as a fix shows it."""
    return float(f"{value:.12g}")


def timing_problem(t_start: float, t_end: float, sample: float, fixed: bool, step: float,
                   spell: Spelling = FILE_SPELLING) -> Optional[Problem]:
    """The first rule the settings break, or None: the span ``t_end - t_start`` is a
    finite number; a fixed step is no longer than the span, takes at most
    :data:`MAX_SCENE_STEPS` steps over it, and divides the sample interval (samples
    are taken at steps).  ``t_end > t_start`` and ``sample > 0`` are the caller's.

    >>> timing_problem(0.0, 1.0, 0.01, True, 0.003).problem
    'the sample interval 0.01 is not a whole multiple of the step 0.003'
    """
    span = t_end - t_start
    if not math.isfinite(span):
        return Problem("time.end", f"the time span from {t_start!r} to {t_end!r} s is too "
                       "long to compute (it overflows a double)",
                       f"give {spell.name('time.start')} and {spell.name('time.end')} "
                       "closer together")
    if not fixed:
        return None
    if step > span:
        # a step that divides the sample interval and is at most a hundredth of the span
        # (past a 1e12 ratio, or below 1, the hundredth itself or the sample interval)
        ratio = sample / (span / 100)
        shorter = sample / math.ceil(ratio) if 1 < ratio < 1e12 else min(sample, span / 100)
        return Problem("integrator.step", f"the step {step!r} is longer than the time span "
                       f"{span!r} s", f"give a step that divides {spell.name('time.sample')}"
                       f", e.g. {spell.write('integrator.step', _short(shorter))} (a "
                       f"hundredth of the span or less)")
    steps = span / step
    if not steps <= MAX_SCENE_STEPS:
        limit = "the C integrator can count" if not steps < _COUNTER_LIMIT \
            else f"the {MAX_SCENE_STEPS:.0e} a scene may take"
        return Problem("integrator.step", f"the step {step!r} takes {steps:.3g} steps over "
                       f"the time span {span!r} s, more than {limit}",
                       _fewer_steps(span, sample, spell))
    ratio = sample / step
    every = round(ratio) if ratio < 2 ** 62 else 0     # a sample of more steps than the span
    if every < 1 or abs(every * step - sample) > REL_TOL * sample:
        nearest = _short(max(every, 1) * step)
        return Problem("time.sample", f"the sample interval {sample!r} is not a whole "
                       f"multiple of the step {step!r}", f"samples are taken at steps: use "
                       f"e.g. {spell.write('time.sample', nearest)}, or change "
                       f"{spell.name('integrator.step')}")
    return None


def _fewer_steps(span: float, sample: float, spell: Spelling) -> str:
    """How to take fewer steps: a step dividing the sample interval with about a
    million steps over the span, else a longer sample interval."""
    ratio = sample / (span / 1e6)
    per_sample = math.floor(ratio) if ratio < 1e12 else 0
    if per_sample >= 1:
        step = _short(sample / per_sample)
        larger = f"larger steps, e.g. {spell.write('integrator.step', step)}"
    else:       # more than a million samples: the samples are too many as well
        larger = f"a longer {spell.name('time.sample')} and {spell.name('integrator.step')}"
    return (f"take {larger}, a shorter time span, or an adaptive method "
            f"({spell.write('integrator.method', 'dopri5')}, which picks its own steps)")

