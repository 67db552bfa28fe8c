"""Fuzz the model loader's expressions with thousands of generated inputs, or the URDF
and MJCF importers with mutated real robots (``--urdf``, ``--mjcf``).

Run from the repository root::

    .venv/bin/python bench/fuzz.py                 # 3000 cases, compile 10 models
    .venv/bin/python bench/fuzz.py --cases 500 --compile 0 --seed 1
    .venv/bin/python bench/fuzz.py --urdf --cases 20000 --workers 2 --compile 5
    .venv/bin/python bench/fuzz.py --mjcf --cases 20000 --workers 2 --compile 5

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

URDF mode (``--urdf``)
    Real URDFs (``tests/data/urdf/*.urdf`` and, when example-robot-data is
    installed, a few small robots of it) are mutated by
    ``modelgen/bench/fuzz_urdf.py`` (numbers, axes, structure, names, XML
    attacks), written to a ``.urdf`` file and read by
    ``modelgen.model.as_spec`` (a fifth of them with ``floating_base=True``),
    in ``--workers`` worker processes.  An accepted file is checked against an
    independent reading of the same XML (``check_accepted``: joint axes, the
    moving links' total mass, centre of mass and inertia); a mismatch is a
    *wrong acceptance*.  A ModelError must name the file and a line.  The first
    ``--compile`` accepted files are also built with ``modelgen.load``.

MJCF mode (``--mjcf``)
    The same with MJCF files: ``modelgen/bench/fuzz_mjcf.py`` mutates a small
    model of every joint kind and, when gymnasium is installed, its MuJoCo
    assets (numbers, joint types, structure, equality constraints, names, XML),
    written to a ``.xml`` file and read by ``modelgen.model.mjcf.import_mjcf``
    (MuJoCo compiles it).  An accepted file is checked against MuJoCo's
    compiled model (``check_accepted``: coordinates, speeds, moving mass).  A
    ModelError must name the file and a line (MuJoCo's) or a key (an element
    of the compiled model); only an empty file has neither.

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
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))


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


#: The worker of the import modes: {imports}, {suffix}, {read} (a spec from ``path``),
#: {check} (problems of an accepted file) and {clean} (a ModelError that names the
#: file and says where) are the format's.
IMPORT_WORKER = r"""
import base64, json, os, shutil, sys, tempfile, time, traceback, warnings
warnings.simplefilter("ignore")
from modelgen.errors import BuildError, ModelError, ModelgenError
{imports}
import modelgen

folder = tempfile.mkdtemp(prefix="mgfuzz_import")
path = os.path.join(folder, "fuzz{suffix}")
for line in sys.stdin:
    case = json.loads(line)
    data = base64.b64decode(case["data"])
    with open(path, "wb") as f:
        f.write(data)
    start = time.perf_counter()
    out = {{"kind": "ok"}}
    try:
        {read}
        out["seconds"] = time.perf_counter() - start
        try:
            problems = {check}
        except Exception as exc:
            problems = [f"the check failed: {{type(exc).__name__}}: {{exc}}"[:200]]
        if problems:
            out = {{"kind": "wrong", "site": problems[0][:200]}}
        elif case["compile"]:
            out["kind"] = "compiled"
            try:
                modelgen.load(spec, os.path.join(folder, "build"))
            except BuildError as exc:
                out = {{"kind": "build_error", "site": str(exc).splitlines()[0][:100]}}
            except ModelgenError as exc:
                reason = str(exc).split(": ", 1)[-1][:40]
                out = {{"kind": "after_validation", "site": f"{{type(exc).__name__}}: {{reason}}"}}
    except ModelError as exc:
        if exc.file == path and ({clean}):
            out = {{"kind": "clean", "site": "ModelError"}}
        else:
            out = {{"kind": "noline", "site": str(exc)[:120]}}
    except ModelgenError as exc:
        out = {{"kind": "clean", "site": type(exc).__name__}}
    except BaseException as exc:
        frame = traceback.extract_tb(exc.__traceback__)[-1]
        out = {{"kind": "other",
               "site": f"{{type(exc).__name__}} at {{frame.filename.split('site-packages/')[-1]}}"
                       f":{{frame.lineno}}"}}
    out.setdefault("seconds", time.perf_counter() - start)    # reading only, not the check
    print(json.dumps(out), flush=True)
shutil.rmtree(folder, ignore_errors=True)
"""

#: format -> its worker: a URDF's ModelError names a line; an MJCF's a line (MuJoCo's,
#: when it refuses the file) or a key (an element of the compiled model), except for
#: an empty file
WORKERS = {
    "urdf": IMPORT_WORKER.format(
        imports="from modelgen.model import as_spec\n"
                "from modelgen.bench.fuzz_urdf import check_accepted",
        suffix=".urdf", read='spec = as_spec(path, floating_base=case["floating_base"])',
        check='check_accepted(spec, data, case["floating_base"])', clean="exc.line"),
    "mjcf": IMPORT_WORKER.format(
        imports="import mujoco\nfrom modelgen.model.mjcf import import_mjcf\n"
                "from modelgen.bench.fuzz_mjcf import check_accepted",
        suffix=".xml", read="imported = import_mjcf(path); spec = imported.model.spec()",
        check="check_accepted(imported, mujoco.MjModel.from_xml_path(path))",
        clean="exc.line or exc.key or not data.strip()"),
}


class Worker:
    """A child process that loads one model per line of JSON."""

    def __init__(self, script: str = WORKER):
        env = dict(os.environ, PYTHONPATH=str(ROOT))
        # in the temporary directory: MuJoCo writes its warnings to MUJOCO_LOG.TXT there
        self.proc = subprocess.Popen([sys.executable, "-c", script], stdin=subprocess.PIPE,
                                     stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                                     text=True, cwd=tempfile.gettempdir(), env=env)

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

    def send(self, case: dict) -> None:
        self.proc.stdin.write(json.dumps(case) + "\n")
        self.proc.stdin.flush()

    def answer(self):
        """The worker's answer to the case sent, or a crash."""
        line = self.proc.stdout.readline()
        if not line:
            return {"kind": "crash", "site": f"exit status {self.proc.wait()}", "seconds": 0.0}
        return json.loads(line)

    def kill(self):
        self.proc.kill()
        self.proc.wait()

    def close(self):
        if self.proc.poll() is None:
            self.proc.stdin.close()
            self.proc.wait()


def urdf_cases(n: int, seed: int):
    """``n`` mutated URDFs (as worker cases), reproducibly."""
    from modelgen.bench.fuzz_urdf import base_texts, mutate
    paths = sorted((ROOT / "tests" / "data" / "urdf").glob("*.urdf"))
    try:
        from modelgen.bench.robots import robots_directory
        directory = robots_directory()
    except ImportError:
        directory = None
    if directory is not None:
        paths += [directory / p for p in (
            "asr_twodof_description/urdf/TwoDofs.urdf", "finger_edu_description/robots/finger_edu.urdf",
            "quadruped_description/urdf/quadruped.urdf", "hector_description/robots/quadrotor_base.urdf",
            "z1_description/urdf/z1.urdf", "bolt_description/robots/bolt.urdf",
            "romeo_description/urdf/romeo_small.urdf", "panda_description/urdf/panda.urdf")]
    return _cases(base_texts(paths), mutate, n, seed, floating=0.2)


def mjcf_cases(n: int, seed: int):
    """``n`` mutated MJCF files (as worker cases), reproducibly."""
    from modelgen.bench.fuzz_mjcf import base_texts, mutate
    return _cases(base_texts(), mutate, n, seed, floating=0.0)


def _cases(texts, mutate, n: int, seed: int, floating: float):
    """``n`` worker cases, each ``mutate`` of one of ``texts`` ((name, text)), a
    fraction ``floating`` of them read with a floating base."""
    import base64
    import random
    # small files more often: a case's cost grows with the file, the bugs do not
    weights = [1 / len(text) for _, text in texts]
    rng = random.Random(seed)
    for _ in range(n):
        name, text = rng.choices(texts, weights)[0]
        data, what = mutate(text, rng)
        data = data.encode() if isinstance(data, str) else data
        yield {"data": base64.b64encode(data).decode(), "floating_base": rng.random() < floating,
               "compile": False, "what": f"{name}: {what}"}


def _pool(args, cases, workers, busy, counts, sites, examples, slow, script):
    """Run the cases on the workers, one case each at a time; (tried, compiled)."""
    t0 = time.perf_counter()
    tried = compiled = 0
    done = False
    while busy or not done:
        for w in range(len(workers)):
            if w in busy or done:
                continue
            case = next(cases, None)
            if case is None:
                done = True
                break
            case["compile"] = compiled < args.compile
            budget = args.hang * (30 if case["compile"] else 1)
            workers[w].send({k: case[k] for k in ("data", "floating_base", "compile")})
            busy[w] = (case, time.monotonic() + budget)
        if not busy:
            break
        now = time.monotonic()
        wait = max(0.0, min(deadline for _, deadline in busy.values()) - now)
        ready, _, _ = select.select([workers[w].proc.stdout for w in busy], [], [], wait)
        finished = []
        for w, (case, deadline) in busy.items():
            if workers[w].proc.stdout in ready:
                out = workers[w].answer()
            elif time.monotonic() >= deadline:
                workers[w].kill()
                out = {"kind": "hang", "seconds": args.hang}
            else:
                continue
            finished.append(w)
            tried += 1
            kind = out["kind"]
            counts[kind] += 1
            compiled += kind == "compiled"
            if kind in ("ok", "compiled"):
                pass
            elif kind in ("clean", "after_validation"):
                sites[(kind, out["site"])] += 1
            else:
                sites[(kind, out.get("site", "")[:60])] += 1
                examples.setdefault((kind, out.get("site", "")[:60]), case["what"])
                print(f"{kind}: {out.get('site', '')}: {case['what']}"[:400], flush=True)
            if kind in ("hang", "crash"):
                workers[w].close()
                workers[w] = Worker(script)
            if kind not in ("compiled", "after_validation", "build_error") \
                    and out["seconds"] > args.budget:
                slow.append((out["seconds"], case["what"]))
            if tried % 1000 == 0:
                print(f"{tried} cases, {tried / (time.perf_counter() - t0):.1f} cases/s",
                      flush=True)
        for w in finished:
            del busy[w]
    for worker in workers:
        worker.close()
    return tried, compiled


def run_import(args, fmt: str) -> int:
    """The URDF or MJCF mode (``fmt``): a pool of workers, one case each at a time."""
    t0 = time.perf_counter()
    counts = collections.Counter()
    sites = collections.Counter()
    examples = {}
    slow = []
    cases = (urdf_cases if fmt == "urdf" else mjcf_cases)(args.cases, args.seed)
    workers = [Worker(WORKERS[fmt]) for _ in range(args.workers)]
    busy = {}                      # worker index -> (case, deadline)
    try:
        tried, compiled = _pool(args, cases, workers, busy, counts, sites, examples, slow,
                                WORKERS[fmt])
    finally:
        for worker in workers:
            if worker.proc.poll() is None:
                worker.kill()
    total = time.perf_counter() - t0
    labels = {"clean": "clean error", "after_validation": "  refused after validation",
              "build_error": "BUILD ERROR (compiler refused)", "other": "RAW EXCEPTION",
              "hang": "HANG", "crash": "CRASH", "wrong": "WRONG ACCEPTANCE",
              "noline": "MODELERROR WITHOUT FILE AND LINE"}
    print()
    print(f"| {'outcome':58} | {'cases':>7} |")
    print(f"|{'-' * 60}|{'-' * 8}:|")
    rows = [("tried", tried),
            ("accepted (a ModelSpec that says what the file says)",
             counts["ok"] + counts["compiled"]),
            ("  of which built and loaded by modelgen.load", counts["compiled"])]
    rows += [(labels[kind] + ": " + site, k) for (kind, site), k in sorted(sites.items())]
    where, wrong = (("line", "axis or inertia differs from the file") if fmt == "urdf" else
                    ("line or key", "sizes or moving mass differ from MuJoCo's"))
    rows += [(f"ModelError with file and {where}", counts["clean"]),
             ("raw exceptions (not ModelgenError)", counts["other"]),
             (f"ModelErrors without file and {where}", counts["noline"]),
             (f"wrong acceptances ({wrong})", counts["wrong"]),
             (f"hangs (> {args.hang:g} s)", counts["hang"]), ("crashes", counts["crash"]),
             (f"slower than the {args.budget:g} s budget", len(slow))]
    for label, k in rows:
        print(f"| {label[:58]:58} | {k:7d} |")
    if slow:
        seconds, what = max(slow)
        print(f"slowest: {seconds:.2f} s: {what}"[:300])
    print(f"total {total:.0f} s, {tried / total:.1f} cases/s with {args.workers} workers")
    bad = sum(counts[k] for k in ("other", "hang", "crash", "build_error", "wrong", "noline"))
    return 1 if bad else 0


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--urdf", action="store_true",
                        help="fuzz the URDF importer with mutated real robots")
    parser.add_argument("--mjcf", action="store_true",
                        help="fuzz the MJCF importer with mutated MuJoCo models")
    parser.add_argument("--workers", type=int, default=1,
                        help="(--urdf, --mjcf) worker processes run in parallel")
    parser.add_argument("--cases", type=int, default=3000)
    parser.add_argument("--compile", type=int, default=10,
                        help="build this many of the models that validate")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--hang", type=float, default=20.0,
                        help="seconds after which a case counts as a hang")
    parser.add_argument("--budget", type=float, default=2.0)
    args = parser.parse_args(argv)
    if args.urdf or args.mjcf:
        return run_import(args, "urdf" if args.urdf else "mjcf")

    from modelgen.bench.fuzz_cases import draw_cases
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
