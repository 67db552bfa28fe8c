"""Fuzz the model loader's expressions with thousands of generated inputs.

Run from the repository root::

    .venv/bin/python bench/fuzz.py                 # 3000 cases, compile 10 models
    .venv/bin/python bench/fuzz.py --cases 500 --compile 0 --seed 1

Method
    The cases come from the generators of ``modelgen/bench/fuzz_cases.py``
    (grammar-shaped texts, random characters with Unicode digits and controls,
    deep nesting, huge constants, YAML numbers), each put into one slot (a base
    angle, a point coordinate or a mass) of a small pendulum model.  The parent
    draws them with hypothesis and hands them one by one to a worker process,
    which calls ``modelgen.model.parse_model``.  A worker that dies is a
    *crash* (the case is recorded and a new worker started); a case that does
    not answer within ``--hang`` seconds is a *hang* (the worker is killed).
    The first ``--compile`` models that validate are also built with
    ``modelgen.load``: a BuildError there means the compiler, not validation,
    refused a model.

Output
    One table: cases tried, models that validated, clean errors (ModelgenError
    subclasses, by class; ModelErrors without a line counted apart), other
    exceptions by site (type and innermost frame), slow cases (over the 2 s
    budget of the tests), hangs, crashes, and the slowest case.
"""
from __future__ import annotations

import argparse
import collections
import json
import os
import select
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from modelgen.bench.fuzz_cases import draw_cases  # noqa: E402

WORKER = r"""
import json, sys, tempfile, time, traceback
from modelgen.errors import BuildError, ModelError, ModelgenError
from modelgen.model import parse_model
import modelgen

for line in sys.stdin:
    case = json.loads(line)
    start = time.perf_counter()
    out = {"kind": "ok"}
    try:
        spec = parse_model(case["text"], "fuzz.yaml")
        if case["compile"]:
            out["kind"] = "compiled"
            try:
                modelgen.load(spec, tempfile.mkdtemp(prefix="mgfuzz"))
            except BuildError as exc:
                out = {"kind": "build_error", "site": str(exc).splitlines()[0][:100]}
            except ModelgenError as exc:
                reason = str(exc).split(": ", 1)[-1][:40]
                out = {"kind": "after_validation", "site": f"{type(exc).__name__}: {reason}"}
    except ModelError as exc:
        out = {"kind": "clean", "site": "ModelError" if exc.line else "ModelError without line"}
    except ModelgenError as exc:
        out = {"kind": "clean", "site": type(exc).__name__}
    except BaseException as exc:
        frame = traceback.extract_tb(exc.__traceback__)[-1]
        out = {"kind": "other",
               "site": f"{type(exc).__name__} at {frame.filename.split('site-packages/')[-1]}"
                       f":{frame.lineno}"}
    out["seconds"] = time.perf_counter() - start
    print(json.dumps(out), flush=True)
"""


class Worker:
    """A child process that loads one model per line of JSON."""

    def __init__(self):
        env = dict(os.environ, PYTHONPATH=str(ROOT))
        self.proc = subprocess.Popen([sys.executable, "-c", WORKER], stdin=subprocess.PIPE,
                                     stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                                     text=True, cwd=ROOT, env=env)

    def run(self, text: str, compile_: bool, timeout: float):
        """The worker's answer, ("hang", None) or ("crash", returncode)."""
        self.proc.stdin.write(json.dumps({"text": text, "compile": compile_}) + "\n")
        self.proc.stdin.flush()
        ready, _, _ = select.select([self.proc.stdout], [], [], timeout)
        if not ready:
            self.proc.kill()
            self.proc.wait()
            return {"kind": "hang", "seconds": timeout}
        line = self.proc.stdout.readline()
        if not line:
            return {"kind": "crash", "site": f"exit status {self.proc.wait()}",
                    "seconds": 0.0}
        return json.loads(line)

    def close(self):
        if self.proc.poll() is None:
            self.proc.stdin.close()
            self.proc.wait()


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", type=int, default=3000)
    parser.add_argument("--compile", type=int, default=10,
                        help="build this many of the models that validate")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--hang", type=float, default=20.0,
                        help="seconds after which a case counts as a hang")
    parser.add_argument("--budget", type=float, default=2.0)
    args = parser.parse_args(argv)

    t0 = time.perf_counter()
    cases = draw_cases(args.cases, args.seed)
    print(f"drew {len(cases)} cases in {time.perf_counter() - t0:.1f} s", flush=True)
    counts = collections.Counter()
    sites = collections.Counter()
    slow = []
    compiled = 0
    worker = Worker()
    for text in cases:
        compile_ = compiled < args.compile
        out = worker.run(text, compile_, args.hang * (10 if compile_ else 1))
        kind = out["kind"]
        counts[kind] += 1
        if kind in ("ok", "compiled", "clean", "after_validation"):
            if kind == "compiled":
                compiled += 1
            if kind in ("clean", "after_validation"):
                sites[(kind, out["site"])] += 1
        else:
            sites[(kind, out.get("site", ""))] += 1
            print(f"{kind}: {out.get('site', '')}: {text!r}"[:400], flush=True)
            if kind in ("hang", "crash"):
                worker.close()
                worker = Worker()
        if kind not in ("compiled", "after_validation", "build_error") \
                and out["seconds"] > args.budget:
            slow.append((out["seconds"], text))
    worker.close()

    tried = len(cases)
    print()
    print(f"{'outcome':58} {'cases':>7}")
    print(f"{'tried':58} {tried:7d}")
    print(f"{'validated (a ModelSpec)':58} {counts['ok'] + counts['compiled']:7d}")
    print(f"{'  of which compiled and loaded':58} {counts['compiled']:7d}")
    for (kind, site), k in sorted(sites.items()):
        label = {"clean": "clean error", "after_validation": "  refused after validation",
                 "build_error": "BUILD ERROR (compiler refused)", "other": "OTHER EXCEPTION",
                 "hang": "HANG", "crash": "CRASH"}[kind]
        print(f"{(label + ': ' + site)[:58]:58} {k:7d}")
    print(f"{'other exceptions (not ModelgenError)':58} {counts['other']:7d}")
    print(f"{'hangs (> %g s)' % args.hang:58} {counts['hang']:7d}")
    print(f"{'crashes':58} {counts['crash']:7d}")
    print(f"{'slower than the %g s budget' % args.budget:58} {len(slow):7d}")
    if slow:
        seconds, text = max(slow)
        print(f"slowest: {seconds:.2f} s: {text!r}"[:300])
    print(f"total {time.perf_counter() - t0:.0f} s")
    bad = counts["other"] + counts["hang"] + counts["crash"] + counts["build_error"]
    return 1 if bad or slow else 0


if __name__ == "__main__":
    sys.exit(main())
