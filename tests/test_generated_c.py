"""The generated C as a product of its own: it builds outside Python, warning-free,
as C99 and as C++, it is deterministic, and the build around it is robust.

* ``examples/embedded_c`` (plain C, ``double_pendulum_integrate`` with rk4 or
  dop853) is built with its Makefile from the output directory alone, and its
  final state is compared with scipy's DOP853 on the same model.
* Every model in ``models/*.yaml``, ``spatial_chain(3)`` and ``spatial_chain(12)``
  (large enough that routines are cut into ``noinline`` parts), and the
  model-independent ``mg_integrate.c`` copied next to them, compile with
  ``cc -std=c99 -Wall -Wextra -Werror -pedantic`` and
  ``c++ -x c++ -std=c++11 -Wall -Wextra -Werror``, whole and as its
  ``MG_PART`` parts, and a small generated ``main`` calls every exported
  function of the header; a chain with derivatives (part 4) as well.
* Golden files: ``tests/golden/double_pendulum.c`` and ``.h`` are the generated
  model source, byte for byte (the integrators, the same for every model, are
  not part of them).  The preamble holds the modelgen version and the model
  hash (which covers the generator version, the model templates, the model),
  so a version bump or any model template change changes the golden files on
  purpose.  After checking the diff, regenerate them with::

      MODELGEN_UPDATE_GOLDEN=1 pytest tests/test_generated_c.py -k golden

Every model here is generated with ``$CC`` and ``$MODELGEN_CFLAGS`` unset (the
default compiler ``cc``), because both enter the model hash printed in the
preamble; the compile checks call ``cc`` and ``c++`` by name.
"""
from __future__ import annotations

import concurrent.futures
import difflib
import json
import os
import re
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import scipy.integrate

import modelgen
from modelgen.model.chains import spatial_chain
from modelgen.codegen.emit import SINGLE_LIMIT, integrator_files

ROOT = Path(__file__).resolve().parent.parent
MODELS = ROOT / "models"
DOUBLE_PENDULUM = MODELS / "double_pendulum.yaml"
EXAMPLE = ROOT / "examples" / "embedded_c"
GOLDEN = Path(__file__).resolve().parent / "golden"
UPDATE_GOLDEN = os.environ.get("MODELGEN_UPDATE_GOLDEN") == "1"
#: A chain whose largest routine exceeds SINGLE_LIMIT statements, so it is cut
#: into noinline parts sharing a work array.
LARGE_CHAIN = 12
#: Environment variables that change the generated text (through the model hash).
HASH_ENV = ("CC", "MODELGEN_CFLAGS")
#: Every function a model exports, without the "<name>_" prefix; written out
#: here rather than taken from modelgen.codegen.emit.public_api, which renders the header.
EXPORTED = ("abi_version", "dimensions", "default_parameters", "mass_matrix", "velocity_terms",
            "generalized_forces", "prepare", "rhs_prepared", "rhs", "inverse_dynamics", "energy",
            "body_poses", "project",
            "system", "jacobian_fd", "integrate", "integrate_batch")
#: The model-independent integrator files copied next to every model's C (and the
#: folder of the files mg_integrate.c includes, which are not compiled alone).
INTEGRATOR = ("mg_integrate.c", "mg_integrate.h")
INTEGRATOR_DIR = "mg_integrate"
C99 = ("cc", "-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic")
CXX11 = ("c++", "-x", "c++", "-std=c++11", "-Wall", "-Wextra", "-Werror")
JOBS = max(2, os.cpu_count() or 2)


def _clean_env(**extra) -> dict:
    env = {k: v for k, v in os.environ.items() if k not in HASH_ENV}
    env.update(extra)
    return env


@pytest.fixture(autouse=True)
def _default_compiler(monkeypatch):
    """Every test sees the same build hash as the shared builds below."""
    for var in HASH_ENV:
        monkeypatch.delenv(var, raising=False)


class _Builds:
    """Fresh builds of the models of this file, generated on first use."""

    def __init__(self, root: Path):
        self.root = root
        self.sources = {path.stem: path for path in sorted(MODELS.glob("*.yaml"))}
        self.sources["spatial_chain_3"] = spatial_chain(3).spec()
        self.sources[f"spatial_chain_{LARGE_CHAIN}"] = spatial_chain(LARGE_CHAIN).spec()
        self.dirs = {}

    def __getitem__(self, name: str) -> Path:
        if name not in self.dirs:
            with pytest.MonkeyPatch.context() as mp:
                for var in HASH_ENV:
                    mp.delenv(var, raising=False)
                g = modelgen.generate_model(self.sources[name], self.root / name)
            assert g.manifest["name"] == name
            self.dirs[name] = self.root / name
        return self.dirs[name]

    def all(self) -> dict:
        return {name: self[name] for name in self.sources}


@pytest.fixture(scope="module")
def generated(tmp_path_factory) -> _Builds:
    """Shared builds: ``generated[name]`` is the directory of that model's build."""
    return _Builds(tmp_path_factory.mktemp("generated"))


def _run(cmd, cwd=None, env=None, timeout=120) -> subprocess.CompletedProcess:
    return subprocess.run([str(c) for c in cmd], cwd=cwd, env=env, timeout=timeout,
                          stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)


def _run_all(commands) -> list:
    """Run (cmd, cwd) pairs in parallel; the failures as readable text."""
    with concurrent.futures.ThreadPoolExecutor(JOBS) as pool:
        results = list(pool.map(lambda c: (c[0], _run(*c)), commands))
    return [f"$ {' '.join(map(str, cmd))}\n{r.stdout}" for cmd, r in results if r.returncode]


# -- the embedded example ------------------------------------------------------

def _run_example(binary: Path, *args) -> dict:
    r = _run([binary, *args])
    assert r.returncode == 0, r.stdout
    fields = {}
    for line in r.stdout.splitlines():
        key, _, value = line.partition(":")
        fields[key] = value
    state = np.array(fields["final state"].split(), dtype=float)
    energy = re.match(r"\s*initial (\S+) J, final (\S+) J", fields["energy"])
    drift = float(fields["energy drift"].split()[0])
    return {"x": state, "e0": float(energy[1]), "e1": float(energy[2]), "drift": drift}


def test_embedded_example_builds_and_runs(generated, tmp_path):
    """The plain-C example (double_pendulum_integrate with rk4, from the output
    directory's files alone) matches DOP853 to RK4's own error at h = 1e-3.

    RK4's global error is C h^4: about 4e-10 for this state after 2 s at
    h = 1e-3 (it shrinks 13-16x per halving of h, as a fourth-order method's
    should).  DOP853 at rtol = atol = 1e-12 is accurate to about 1e-12, so
    TOL = 1e-8 leaves a margin of ~25 over RK4's truncation error, and any
    mistake in the model or the integrator exceeds it by orders of magnitude
    (a stage weight of 1.9 instead of 2 gives an error of 1.7).
    The convergence ratio between h = 2e-3 and 1e-3 (16 in theory, 8 for a
    third-order method) checks the order itself.
    """
    TOL, T, X0 = 1e-8, 2.0, [-0.5, 0.5, 0.0, 0.0]
    model_dir, build = generated["double_pendulum"], tmp_path / "build"
    tree_before = sorted(p.name for p in EXAMPLE.iterdir())
    r = _run(["make", "-C", EXAMPLE, f"MODEL_DIR={model_dir}", f"BUILD_DIR={build}"])
    assert r.returncode == 0, r.stdout
    assert sorted(p.name for p in EXAMPLE.iterdir()) == tree_before, "make wrote into the source tree"
    binary = build / "double_pendulum_sim"

    cm = modelgen.load(DOUBLE_PENDULUM, model_dir)
    ref = scipy.integrate.solve_ivp(cm.rhs, (0.0, T), X0, method="DOP853",
                                    rtol=1e-12, atol=1e-12)
    assert ref.success
    x_ref = ref.y[:, -1]

    fine = _run_example(binary, T, 1e-3, *X0)
    coarse = _run_example(binary, T, 2e-3, *X0)
    err_fine = np.linalg.norm(fine["x"] - x_ref)
    err_coarse = np.linalg.norm(coarse["x"] - x_ref)
    assert err_fine < TOL, (fine["x"], x_ref)
    assert err_coarse / err_fine > 10, (err_coarse, err_fine)

    # energy: the C program's numbers are those of the compiled model, and drift little
    q, qd = fine["x"][:2], fine["x"][2:]
    assert fine["e1"] == pytest.approx(cm.energy(q, qd).sum(), rel=1e-13, abs=1e-13)
    assert fine["e0"] == pytest.approx(cm.energy(X0[:2], X0[2:]).sum(), rel=1e-13, abs=1e-13)
    assert abs(fine["drift"]) < 1e-9 * abs(fine["e0"])
    default = _run_example(binary)                      # 10 s at h = 1e-3
    assert abs(default["drift"]) < 1e-8 * abs(default["e0"])

    # a failure status (a NaN state) stops the program with the integrator's reason
    r = _run([binary, 1, 1e-3, "nan", 0, 0, 0])
    assert r.returncode != 0
    assert "NaN or Inf in the state" in r.stdout
    # dop853 (h = 0) through the same entry point, to its tolerance
    tight = _run_example(binary, T, 0, *X0)
    assert np.linalg.norm(tight["x"] - x_ref) < 1e-9


@pytest.fixture(scope="module")
def example_binary(generated, tmp_path_factory) -> Path:
    """The embedded example, built once with its Makefile."""
    build = tmp_path_factory.mktemp("example")
    r = _run(["make", "-C", EXAMPLE, f"MODEL_DIR={generated['double_pendulum']}",
              f"BUILD_DIR={build}"])
    assert r.returncode == 0, r.stdout
    return build / "double_pendulum_sim"


def test_the_examples_generate_target_writes_the_model_it_builds(tmp_path):
    """``make generate`` (the docs' first step) runs this checkout's modelgen: it
    used to call ``python -m modelgen.cli``, which is not runnable."""
    model_dir = tmp_path / "double_pendulum"
    r = _run(["make", "-C", EXAMPLE, "generate", f"PYTHON={sys.executable}",
              f"MODEL_DIR={model_dir}"])
    assert r.returncode == 0, r.stdout
    assert (model_dir / "double_pendulum.c").is_file()
    assert (model_dir / "double_pendulum.h").is_file()


def test_embedded_example_prints_what_its_readme_shows(example_binary):
    """The README's output block is the program's output, digit for digit (the model
    code computes the same bits on every machine: mg_sin/mg_cos, no libm)."""
    readme = (EXAMPLE / "README.md").read_text()
    shown = re.search(r"```\n(steps: .*?)```", readme, re.DOTALL).group(1)
    r = _run([example_binary])
    assert r.returncode == 0, r.stdout
    assert r.stdout == shown


@pytest.mark.parametrize("args, why", [
    (["abc"], "t_end 'abc' is not a finite number"),
    (["2x"], "t_end '2x' is not a finite number"),
    ([""], "t_end '' is not a finite number"),
    (["0"], "need t_end > 0"),
    (["-1"], "need t_end > 0"),
    (["1e999"], "t_end '1e999' is not a finite number"),
    (["inf"], "t_end 'inf' is not a finite number"),
    (["1", "-1e-3"], "need t_end > 0, h >= 0"),
    (["1", "nan"], "h 'nan' is not a finite number"),
    (["1e9", "1e-3"], "t_end / h <= 1e8 steps"),
    (["1", "1e-3", "0.1"], "expected 0, 1, 2 or 6 arguments, got 3"),
    (["1", "1e-3", "0", "0", "0", "0", "7"], "expected 0, 1, 2 or 6 arguments, got 7"),
    (["1", "1e-3", "0", "zero", "0", "0"], "state 'zero' is not a number"),
])
def test_embedded_example_refuses_bad_arguments_with_its_usage(example_binary, args, why):
    """Bad arguments are refused with the usage line and a non-zero exit before
    anything runs (atof read 'abc' as 0 and quietly ran 0 steps)."""
    r = _run([example_binary, *args])
    assert r.returncode != 0, r.stdout
    assert why in r.stdout and "usage: " in r.stdout, r.stdout
    assert "steps:" not in r.stdout and "final state" not in r.stdout


# -- compiling the C on its own -----------------------------------------------------

PROTOTYPE = re.compile(r"^(int|void) (\w+)\((.*)\);$", re.M)   # params may hold a function pointer


def _exported(model_dir: Path) -> tuple:
    """EXPORTED, and a constrained model's constraint functions (docs/constraints.md)."""
    info = json.loads((model_dir / "manifest.json").read_text()).get("constraints")
    if not info:
        return EXPORTED
    return EXPORTED + ("constraint_jacobian", "constrain") + \
        (("constraint_residuals",) if info["holonomic"] else ())


def _prototypes(model_dir: Path, name: str) -> list:
    """(return type, function, parameters) of every prototype in the header."""
    protos = PROTOTYPE.findall((model_dir / f"{name}.h").read_text())
    assert sorted(f for _, f, _ in protos) == sorted(f"{name}_{s}" for s in _exported(model_dir)), \
        f"{name}.h does not declare exactly the expected functions"
    return protos


def _checker(model_dir: Path, name: str) -> str:
    """A C function ``check_<name>()`` calling every function of the header once.

    Arrays are sized from the header's constants; it returns the number of
    failures (ABI mismatch, nonzero rhs status, non-finite derivative).
    """
    N = name.upper()
    arg = {"double t": "0.25", "const double *q": "x", "const double *qd": f"x + {N}_NQ",
           "const double *x": "x", "const double *u": "u", "const double *p": "p",
           "double *p": "p", "const double *qdd": f"x + {N}_NQ"}
    lines = [
        f"static int event_{name}(void *ctx, double t, const double *x, double *g)",
        "{",
        "    (void)ctx;",
        "    (void)x;",
        "    g[0] = t - 0.004;",
        "    return 0;",
        "}",
        "",
        f"static int check_{name}(void)",
        "{",
        f"    double p[{N}_NP + 1], x[{N}_NX], u[{N}_NU + 1];",
        f"    double out[{N}_NQ * {N}_NQ + 16 * {N}_NBODIES + {N}_NX + 1];",
        "    int i, failures = 0;",
        f"    for (i = 0; i < {N}_NX; ++i) x[i] = 0.1 * (i + 1);",
        f"    for (i = 0; i <= {N}_NU; ++i) u[i] = 0.0;",
        f"    {name}_default_parameters(p);",
    ]
    for ret, fn, params in _prototypes(model_dir, name):
        if fn == f"{name}_jacobian_fd":
            lines += [
                "    {",
                f"        double J[{N}_NX * {N}_NX];",
                f"        if ({fn}(0.25, x, u, p, J) != 0) ++failures;",
                f"        for (i = 0; i < {N}_NX * {N}_NX; ++i) if (!(J[i] - J[i] == 0.0)) ++failures;",
                "    }",
                f'    printf("called {fn}\\n");']
            continue
        if fn == f"{name}_dimensions":
            lines += [
                "    {",
                "        int d[7];",
                f"        {fn}(d);",
                f"        if (d[0] != {N}_NQ || d[1] != {N}_NX || d[2] != {N}_NP || d[3] != {N}_NU"
                f" || d[4] != {N}_NBODIES || d[5] != {N}_NY || d[6] != {N}_NV) ++failures;",
                "    }",
                f'    printf("called {fn}\\n");']
            continue
        if fn == f"{name}_prepare":
            lines += [f'    printf("called {fn}\\n");']     # called with rhs_prepared
            continue
        if fn == f"{name}_rhs_prepared":
            # the same xdot, bit for bit, as the rhs that prepares pd itself
            lines += [
                "    {",
                f"        double pd[{N}_NPD_ALLOC], a[{N}_NX], b[{N}_NX];",
                f"        {name}_prepare(p, pd);",
                f"        if ({fn}(0.25, x, u, p, pd, a) != 0 || {name}_rhs(0.25, x, u, p, b) != 0)"
                " ++failures;",
                "        if (memcmp(a, b, sizeof a) != 0) ++failures;",
                "    }",
                f'    printf("called {fn}\\n");']
            continue
        if fn == f"{name}_system":
            lines += [
                "    {",
                "        mg_system sys;",
                f"        {fn}(&sys);",
                f"        if (sys.nx != {N}_NX || sys.nu != {N}_NU || sys.np != {N}_NP || "
                f"sys.ny != {N}_NY || !sys.rhs) ++failures;",
                "    }",
                f'    printf("called {fn}\\n");']
            continue
        if fn == f"{name}_integrate":
            # dopri5 over 10 ms sampled at 5 and 10 ms, one event at t = 4 ms
            lines += [
                "    {",
                f"        double rt[{N}_NX], at[{N}_NX], te[2] = {{0.005, 0.01}}, to[2], xo[2 * {N}_NX];",
                f"        double tf[4], xf[4 * {N}_NX], stop[MG_STOP_X + {N}_NX], work[{N}_WORK_SIZE];",
                "        int dir = 1, term = 0, wh[4];",
                "        mg_options opt;",
                "        mg_output out;",
                "        mg_stats st;",
                "        memset(&opt, 0, sizeof opt);",
                "        memset(&out, 0, sizeof out);",
                f"        for (i = 0; i < {N}_NX; ++i) {{ rt[i] = 1e-8; at[i] = 1e-10; }}",
                "        opt.method = MG_METHOD_DOPRI5; opt.rtol = rt; opt.atol = at; opt.max_steps = 1000;",
                f"        opt.n_events = 1; opt.events = event_{name}; opt.direction = &dir; opt.terminal = &term;",
                "        out.capacity = 2; out.t_eval = te; out.t = to; out.x = xo; out.stop = stop;",
                "        out.events_capacity = 4; out.t_events = tf; out.x_events = xf; out.which_events = wh;",
                f"        if ({fn}(0.0, 0.01, x, p, 0, &opt, &out, &st, work) != MG_STATUS_SUCCESS) ++failures;",
                "        if (out.n != 2 || to[1] != 0.01 || out.n_events != 1 || wh[0] != 0) ++failures;",
                "        if (!(tf[0] > 0.004 - 1e-12 && tf[0] < 0.004 + 1e-12) || stop[0] != 0.01) ++failures;",
                "    }",
                f'    printf("called {fn}\\n");']
            continue
        if fn == f"{name}_integrate_batch":
            # two identical runs of rk4 (10 steps), final states only
            lines += [
                "    {",
                f"        double X[2 * {N}_NX], te[1] = {{0.01}}, xo[2 * {N}_NX], stop[2 * (MG_STOP_X + {N}_NX)];",
                f"        double work[MG_WORK_SIZE({N}_NX, {N}_NU, 0)];",
                "        long n_o[2];",
                "        int sts[2];",
                "        mg_options opt;",
                "        mg_stats st[2];",
                "        memset(&opt, 0, sizeof opt);",
                f"        for (i = 0; i < {N}_NX; ++i) X[i] = X[{N}_NX + i] = x[i];",
                "        opt.method = MG_METHOD_RK4; opt.fixed_step = 1e-3; opt.max_steps = 100;",
                f"        if ({fn}(2, 0.0, 0.01, X, p, 0, 0, &opt, 1, te, xo, 0, n_o, sts, st, stop, work) != 0) ++failures;",
                f"        if (n_o[0] != 1 || n_o[1] != 1 || sts[0] != 0 || xo[0] != xo[{N}_NX] || st[0].naccept != 10) ++failures;",
                "    }",
                f'    printf("called {fn}\\n");']
            continue
        args = []
        for param in (s.strip() for s in params.split(",")):
            if param == "void":
                continue
            if param not in arg and not param.startswith("double *"):
                raise AssertionError(f"{fn}: parameter {param!r} unknown to this test")
            args.append(arg.get(param, "out"))
        call = f"{fn}({', '.join(args)})"
        if fn == f"{name}_abi_version":
            lines.append(f"    if ({call} != {N}_ABI_VERSION) ++failures;")
        elif fn == f"{name}_rhs":
            lines += [f"    if ({call} != 0) ++failures;",
                      f"    for (i = 0; i < {N}_NX; ++i) if (!(out[i] - out[i] == 0.0)) ++failures;"]
        else:
            lines.append(f"    {'(void)' if ret != 'void' else ''}{call};")
        lines.append(f'    printf("called {fn}\\n");')
    lines += ["    return failures;", "}", ""]
    return "\n".join(lines)


def _main_source(models: dict) -> str:
    """A main (valid C99 and C++11) that checks every model of ``models``."""
    head = ["#include <stdio.h>", "#include <string.h>"] + [f'#include "{n}.h"' for n in models] + [""]
    body = [_checker(d, n) for n, d in models.items()]
    calls = " + ".join(f"check_{n}()" for n in models)
    main = ["int main(void)", "{", f"    int failures = {calls};",
            '    printf("failures: %d\\n", failures);', "    return failures != 0;", "}", ""]
    return "\n".join(head + body + main)


def _defined_globals(obj: Path) -> list:
    r = _run(["nm", "-g", "--defined-only", obj])
    assert r.returncode == 0, r.stdout
    return sorted(line.split()[-1] for line in r.stdout.splitlines() if line.strip())


#: The MG_PART values a build compiles (model.c.j2; 4 holds code only with derivatives).
PARTS = (1, 2, 3, 4)


def test_generated_c_compiles_warning_free_as_c99_and_cxx(generated, tmp_path):
    """Strict C99 (-pedantic) and C++11, whole and per MG_PART; nothing missing.

    Unoptimised compiles, to keep this fast: the shared builds already passed
    the build's own ``-O2 -Wall -Wextra -Werror``, which covers the warnings
    that need optimisation; the large chain's part 1 is compiled at -O1 too,
    since a routine cut into parts is read only by optimizing compiles (at -O0
    its flat text is).  Each model links three ways (C main + C object,
    C++ main + the C parts, C main + the C++-compiled parts), always with the
    ``mg_integrate.c`` of its output directory (compiled the same way), each
    program calls every function of the header, and ``nm`` shows that the
    model object defines exactly the prefixed functions and the parts split
    them, and that mg_integrate defines only ``mg_`` functions.
    """
    large = f"spatial_chain_{LARGE_CHAIN}"
    ops = json.loads((generated[large] / "manifest.json").read_text())["ops"]
    assert max(o["statements"] for o in ops.values()) > SINGLE_LIMIT, \
        f"{large} is no longer chunked; use a larger chain to cover the noinline parts"
    assert f"{large}_rhs_part0(" in (generated[large] / f"{large}.c").read_text()

    models = generated.all()
    compiles, links, binaries = [], [], {}
    for name, src in models.items():
        out = tmp_path / name
        out.mkdir()
        (out / "main.c").write_text(_main_source({name: src}))
        inc = f"-I{src}"
        assert sorted(p.name for p in src.iterdir() if p.suffix in (".c", ".h")) == \
            sorted([f"{name}.c", f"{name}.h", *INTEGRATOR]), "the output directory is not self-contained"
        assert sorted(f"{INTEGRATOR_DIR}/{p.name}" for p in (src / INTEGRATOR_DIR).iterdir()) == \
            [f for f in integrator_files() if f.startswith(f"{INTEGRATOR_DIR}/")]
        for tag, flags in (("all", []), *((str(k), [f"-DMG_PART={k}"]) for k in PARTS)):
            compiles.append(([*C99, *flags, "-c", src / f"{name}.c", "-o", f"c_{tag}.o"], out))
            compiles.append(([*CXX11, *flags, "-c", src / f"{name}.c", "-o", f"cxx_{tag}.o"], out))
        if name == large:   # the query routines' parts, which only optimizing compiles read
            compiles.append(([*C99, "-O1", "-DMG_PART=1", "-c", src / f"{name}.c", "-o",
                              "c_optimized_1.o"], out))
        compiles.append(([*C99, "-c", src / "mg_integrate.c", "-o", "c_mg.o"], out))
        compiles.append(([*CXX11, "-c", src / "mg_integrate.c", "-o", "cxx_mg.o"], out))
        compiles.append(([*C99, inc, "-c", "main.c", "-o", "main_c.o"], out))
        compiles.append(([*CXX11, "-pedantic", inc, "-c", "main.c", "-o", "main_cxx.o"], out))
        # C main + whole C file; C++ main + the C parts (extern "C");
        # C main + the C++-compiled parts
        for exe, cmd in (("c_all", ["cc", "main_c.o", "c_all.o", "c_mg.o"]),
                         ("cxx_main_c_parts", ["c++", "main_cxx.o",
                                               *(f"c_{k}.o" for k in PARTS), "c_mg.o"]),
                         ("c_main_cxx_parts", ["c++", "main_c.o",
                                               *(f"cxx_{k}.o" for k in PARTS), "cxx_mg.o"])):
            links.append(([*cmd, "-o", exe, "-lm"], out))
            binaries[(name, exe)] = out / exe

    failures = _run_all(compiles)
    assert not failures, "generated C does not compile cleanly:\n" + "\n".join(failures)
    failures = _run_all(links)
    assert not failures, "generated C does not link:\n" + "\n".join(failures)
    for (name, exe), binary in binaries.items():
        r = _run([binary])
        assert r.returncode == 0, f"{name} {exe}:\n{r.stdout}"
        for suffix in _exported(models[name]):
            assert f"called {name}_{suffix}\n" in r.stdout, f"{name} {exe}:\n{r.stdout}"

    for name in models:
        out = tmp_path / name
        exported = sorted(f"{name}_{s}" for s in _exported(models[name]))
        assert _defined_globals(out / "c_all.o") == exported, name
        parts = [g for k in PARTS for g in _defined_globals(out / f"c_{k}.o")]
        assert sorted(parts) == exported, f"{name}: MG_PART parts overlap or miss symbols"
        assert all(g.startswith("mg_") for g in _defined_globals(out / "c_mg.o"))


def _symbols(obj: Path) -> dict:
    """Defined global symbols of an object file -> their visibility (readelf)."""
    r = _run(["readelf", "-sW", obj])
    assert r.returncode == 0, r.stdout
    return {f[7]: f[5] for f in (line.split() for line in r.stdout.splitlines())
            if len(f) >= 8 and f[4] in ("GLOBAL", "WEAK") and f[6] != "UND"}


def test_derivatives_parts_split_the_header_and_hide_what_they_share(tmp_path):
    """A model with derivatives compiles as C99 (-pedantic) and C++, whole and per
    MG_PART; the parts define each function of its header once, the straight line
    that part 3's solve calls (``<name>_derivative_terms``) only in part 4 and
    hidden, and neither it nor anything else unprefixed leaves the library."""
    name = "spatial_chain_3"
    g = modelgen.generate_model(spatial_chain(3).spec(), tmp_path / "build", derivatives=True)
    src = g.build.directory
    header = sorted(f for _, f, _ in PROTOTYPE.findall((src / f"{name}.h").read_text()))
    assert f"{name}_derivatives" in header and f"{name}_derivative_terms" not in header
    commands = [c for c in g.manifest["compile_commands"] if "-DMG_PART=" in c]
    if commands:     # a build in parts (more than one core): the largest part first
        assert "-DMG_PART=4" in commands[0] and len(commands) == len(PARTS)
    compiles = []
    for tag, flags in (("all", []), *((str(k), [f"-DMG_PART={k}"]) for k in PARTS)):
        compiles.append(([*C99, *flags, "-c", src / f"{name}.c", "-o", f"c_{tag}.o"], tmp_path))
        compiles.append(([*CXX11, *flags, "-c", src / f"{name}.c", "-o", f"cxx_{tag}.o"],
                         tmp_path))
    failures = _run_all(compiles)
    assert not failures, "generated C does not compile cleanly:\n" + "\n".join(failures)
    shared = f"{name}_derivative_terms"
    for lang in ("c", "cxx"):
        whole = _symbols(tmp_path / f"{lang}_all.o")
        assert sorted(whole) == header and set(whole.values()) == {"DEFAULT"}
        parts = {k: _symbols(tmp_path / f"{lang}_{k}.o") for k in PARTS}
        public = sorted(s for syms in parts.values() for s, vis in syms.items()
                        if vis == "DEFAULT")
        assert public == header, f"{lang}: MG_PART parts overlap or miss symbols"
        hidden = {k: sorted(s for s, vis in syms.items() if vis != "DEFAULT")
                  for k, syms in parts.items()}
        assert hidden == {1: [], 2: [], 3: [], 4: [shared]}, hidden
    r = _run(["nm", "-D", "--defined-only", g.build.module_path])
    assert r.returncode == 0, r.stdout
    exported = [line.split()[-1] for line in r.stdout.splitlines() if line.strip()]
    assert f"{name}_derivatives" in exported and shared not in exported


def test_derivatives_built_in_one_part_match_central_differences(tmp_path, monkeypatch):
    """On one core the whole file is one compile (no MG_PART), where the shared
    straight line is static; its derivatives still match the rhs's central
    differences."""
    from modelgen.codegen import build
    from test_derivatives import _check_against_differences
    monkeypatch.setattr(build, "core_count", lambda: 1)
    cm = modelgen.load(spatial_chain(4).spec(), tmp_path / "build", derivatives=True,
                       force=True)
    commands = cm.manifest["compile_commands"]
    assert len(commands) == 1 and "MG_PART" not in commands[0]
    _check_against_differences(cm, seed=4)


def test_two_models_link_into_one_program_without_symbol_clashes(generated, tmp_path):
    models = {n: generated[n] for n in ("double_pendulum", "simple_pendulum")}
    (tmp_path / "main.c").write_text(_main_source(models))
    incs = [f"-I{d}" for d in models.values()]
    objs = [f"{n}.o" for n in models]
    compiles = [([*C99, *incs, "-c", "main.c", "-o", "main.o"], tmp_path)]
    compiles += [([*C99, "-O2", "-c", d / f"{n}.c", "-o", f"{n}.o"], tmp_path)
                 for n, d in models.items()]
    # both directories hold the same mg_integrate.c: it is compiled once for both
    mg = [(d / "mg_integrate.c").read_bytes() for d in models.values()]
    assert mg[0] == mg[1]
    compiles.append(([*C99, "-O2", "-c", models["double_pendulum"] / "mg_integrate.c", "-o",
                      "mg_integrate.o"], tmp_path))
    failures = _run_all(compiles)
    assert not failures, "\n".join(failures)
    r = _run(["cc", "main.o", *objs, "mg_integrate.o", "-o", "two_models", "-lm"], cwd=tmp_path)
    assert r.returncode == 0, r.stdout
    r = _run([tmp_path / "two_models"])
    assert r.returncode == 0 and "failures: 0" in r.stdout, r.stdout
    symbols = [s for o in objs for s in _defined_globals(tmp_path / o)]
    assert len(symbols) == len(set(symbols)) == 2 * len(EXPORTED)


# -- determinism and golden files ---------------------------------------------------

_GENERATE = """
import sys
import modelgen
from modelgen.model.chains import spatial_chain
modelgen.generate_model(sys.argv[1], sys.argv[2] + "/double_pendulum", force=True)
modelgen.generate_model(spatial_chain(3).spec(), sys.argv[2] + "/spatial_chain_3", force=True)
"""


def _sources(directory: Path, name: str) -> dict:
    return {ext: (directory / f"{name}{ext}").read_bytes() for ext in (".c", ".h")}


def test_generated_c_is_deterministic(generated, tmp_path):
    # two subprocesses with other hash seeds run while this process generates twice
    seeds = ("1", "2") if os.environ.get("PYTHONHASHSEED") not in ("1", "2") else ("3", "4")
    procs = [subprocess.Popen([sys.executable, "-c", _GENERATE, str(DOUBLE_PENDULUM),
                               str(tmp_path / f"seed{s}")], cwd=ROOT,
                              env=_clean_env(PYTHONHASHSEED=s), stdout=subprocess.PIPE,
                              stderr=subprocess.STDOUT, text=True) for s in seeds]
    # the shared builds are a first derivation in this process, this is a second
    out = tmp_path / "again"
    modelgen.generate_model(DOUBLE_PENDULUM, out / "double_pendulum", force=True)
    modelgen.generate_model(spatial_chain(3).spec(), out / "spatial_chain_3", force=True)
    runs = {"second run in this process": out}
    for s, proc in zip(seeds, procs):
        output, _ = proc.communicate(timeout=120)
        assert proc.returncode == 0, output
        runs[f"PYTHONHASHSEED={s}"] = tmp_path / f"seed{s}"
    for name in ("double_pendulum", "spatial_chain_3"):
        expected = _sources(generated[name], name)
        for label, out in runs.items():
            got = _sources(out / name, name)
            for ext in (".c", ".h"):
                assert got[ext] == expected[ext], \
                    f"{name}{ext} differs ({label}):\n{_diff(expected[ext], got[ext], label)}"


def test_generated_c_does_not_depend_on_where_the_model_file_lies(generated, tmp_path):
    copy = tmp_path / "elsewhere" / "double_pendulum.yaml"
    copy.parent.mkdir()
    copy.write_bytes(DOUBLE_PENDULUM.read_bytes())
    modelgen.generate_model(copy, tmp_path / "out")
    expected = _sources(generated["double_pendulum"], "double_pendulum")
    got = _sources(tmp_path / "out", "double_pendulum")
    assert got == expected, _diff(expected[".c"], got[".c"], "model file copied elsewhere")


def _diff(old: bytes, new: bytes, label: str, lines: int = 60) -> str:
    diff = difflib.unified_diff(old.decode().splitlines(keepends=True),
                                new.decode().splitlines(keepends=True),
                                fromfile="expected", tofile=label)
    return "".join(list(diff)[:lines])


def test_golden_double_pendulum(generated):
    got = _sources(generated["double_pendulum"], "double_pendulum")
    if UPDATE_GOLDEN:
        GOLDEN.mkdir(exist_ok=True)
        for ext, data in got.items():
            (GOLDEN / f"double_pendulum{ext}").write_bytes(data)
    problems = []
    for ext, data in got.items():
        golden = GOLDEN / f"double_pendulum{ext}"
        if not golden.is_file():
            problems.append(f"{golden} is missing")
            continue
        if golden.read_bytes() != data:
            diff = difflib.unified_diff(
                golden.read_text().splitlines(keepends=True), data.decode().splitlines(keepends=True),
                fromfile=f"tests/golden/double_pendulum{ext}",
                tofile=f"generated/double_pendulum{ext}")
            problems.append("".join(list(diff)[:60]))
    if problems:
        pytest.fail("generated double_pendulum differs from the golden files:\n"
                    + "\n".join(problems)
                    + "\nIf the change is intended (a new version or template changes the "
                    "preamble too), regenerate them with\n"
                    "    MODELGEN_UPDATE_GOLDEN=1 pytest tests/test_generated_c.py -k golden")


# -- the build around the C -----------------------------------------------------------

def test_build_cache_reuses_unchanged_model(tmp_path):
    spec = modelgen.as_spec(MODELS / "simple_pendulum.yaml")
    first = modelgen.generate_model(spec, tmp_path)
    assert not first.build.cached
    so = first.build.module_path
    mtimes = {p.name: p.stat().st_mtime_ns for p in (so, tmp_path / "simple_pendulum.c")}

    start = time.perf_counter()
    second = modelgen.generate_model(MODELS / "simple_pendulum.yaml", tmp_path)
    elapsed = time.perf_counter() - start
    assert second.build.cached
    assert elapsed < 0.5, elapsed
    assert second.build.module_path == so
    assert {p.name: p.stat().st_mtime_ns for p in (so, tmp_path / "simple_pendulum.c")} == mtimes

    # a changed model is rebuilt, not served from the cache
    import dataclasses
    changed = dataclasses.replace(spec, parameters=(("L", 2.0),) + spec.parameters[1:])
    third = modelgen.generate_model(changed, tmp_path)
    assert not third.build.cached
    assert third.build.module_path != so


def test_a_changed_model_reuses_the_compiled_integrators(monkeypatch, tmp_path):
    """The integrators are compiled once into the cache; an edited model compiles only
    its own code.  Changed integrator sources give another object and rebuild the
    modules that linked the old one."""
    import dataclasses
    from modelgen.codegen import build, pipeline
    monkeypatch.setenv("MODELGEN_CACHE_DIR", str(tmp_path / "cache"))
    spec = modelgen.as_spec(MODELS / "simple_pendulum.yaml")
    first = modelgen.generate_model(spec, tmp_path / "a")
    objects = sorted((tmp_path / "cache").glob("mg_integrate-*.o"))
    assert len(objects) == 1
    stamp = objects[0].stat().st_mtime_ns
    changed = dataclasses.replace(spec, parameters=(("L", 2.0),) + spec.parameters[1:])
    second = modelgen.generate_model(changed, tmp_path / "b")
    assert not second.build.cached
    assert sorted((tmp_path / "cache").glob("mg_integrate-*.o")) == objects
    assert objects[0].stat().st_mtime_ns == stamp
    assert not any("mg_integrate" in c for c in second.manifest["compile_commands"])
    assert not first.manifest["integrators"]["cached"] and second.manifest["integrators"]["cached"]
    assert first.manifest["build_hash"] != second.manifest["build_hash"]
    assert (tmp_path / "a" / "mg_integrate.c").read_bytes() == \
        (tmp_path / "b" / "mg_integrate.c").read_bytes()

    sources = pipeline.integrator_sources()
    edited = dict(sources, **{"mg_integrate.c": sources["mg_integrate.c"] + "/* edited */\n"})
    monkeypatch.setattr(pipeline, "integrator_sources", lambda: edited)
    third = modelgen.generate_model(spec, tmp_path / "a")
    assert not third.build.cached
    assert len(list((tmp_path / "cache").glob("mg_integrate-*.o"))) == 2
    assert (tmp_path / "a" / "mg_integrate.c").read_text().endswith("/* edited */\n")
    assert build.integrator_hash(edited) != build.integrator_hash(sources)
    # every included file is part of the key, and is copied into the output directory
    part = "mg_integrate/rodas.c"
    edited = dict(sources, **{part: sources[part] + "/* edited */\n"})
    assert build.integrator_hash(edited) != build.integrator_hash(sources)
    assert (tmp_path / "a" / part).read_text() == sources[part]


_RACE = """
import sys, time
from pathlib import Path
import modelgen
spec = modelgen.as_spec(sys.argv[1])
barrier = Path(sys.argv[3])
(barrier / sys.argv[4]).touch()
deadline = time.monotonic() + 60
while len(list(barrier.iterdir())) < 2 and time.monotonic() < deadline:
    time.sleep(0.002)
print("cached", modelgen.generate_model(spec, sys.argv[2]).build.cached)
"""

_CHECK_MODULE = """
import ctypes, json, sys
from pathlib import Path
d = Path(sys.argv[1])
m = json.loads((d / "manifest.json").read_text())
lib = ctypes.CDLL(str(d / m["module_file"]))     # a plain C library: no modelgen needed
D = ctypes.c_double
p, u, out = (D * 5)(), (D * 1)(), (D * 4)()
lib.double_pendulum_default_parameters(p)
lib.double_pendulum_rhs.argtypes = [D] + [ctypes.POINTER(D)] * 4
status = lib.double_pendulum_rhs(0.0, (D * 4)(-0.5, 0.5, 0.0, 0.0), u, p, out)
print(status, *[repr(v) for v in out])
"""


def test_concurrent_builds_both_succeed(generated, tmp_path):
    out, barrier = tmp_path / "out", tmp_path / "barrier"
    barrier.mkdir()
    procs = [subprocess.Popen([sys.executable, "-c", _RACE, str(DOUBLE_PENDULUM), str(out),
                               str(barrier), f"p{i}"], cwd=ROOT, env=_clean_env(),
                              stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
             for i in range(2)]
    outputs = [p.communicate(timeout=120)[0] for p in procs]
    for proc, output in zip(procs, outputs):
        assert proc.returncode == 0, output
        # both found no build and compiled at the same time: the race happened
        assert "cached False" in output, output

    names = sorted(p.name for p in out.iterdir())
    manifest = json.loads((out / "manifest.json").read_text())
    assert names == sorted(["manifest.json", "double_pendulum.c", "double_pendulum.h",
                            *INTEGRATOR, INTEGRATOR_DIR, manifest["module_file"]]), names
    assert not [n for n in names if n.startswith(".build-")]

    r = _run([sys.executable, "-c", _CHECK_MODULE, out])
    assert r.returncode == 0, r.stdout
    status, *xdot = r.stdout.split()
    expected = modelgen.load(DOUBLE_PENDULUM, generated["double_pendulum"]).rhs(
        0.0, [-0.5, 0.5, 0.0, 0.0])
    assert status == "0"
    np.testing.assert_array_equal(np.array(xdot, dtype=float), expected)


def test_compiler_failure_raises_build_error_with_command_and_output(monkeypatch, tmp_path):
    monkeypatch.setenv("CC", "cc -DMG_FORCE_ERROR -include /nonexistent.h")
    with pytest.raises(modelgen.BuildError) as info:
        modelgen.generate_model(MODELS / "simple_pendulum.yaml", tmp_path)
    err = info.value
    message = str(err)
    assert "cc -DMG_FORCE_ERROR -include /nonexistent.h" in message
    assert " ".join(err.command) in message
    assert "/nonexistent.h" in err.output and err.output in message
    assert "error" in err.output.lower()
    # nothing half-built is left behind
    assert sorted(p.name for p in tmp_path.iterdir()) == []


def test_routines_in_parts_and_flat_agree(tmp_path, monkeypatch):
    """A query routine cut into noinline parts also carries its text as one function
    of locals for compilers that do not optimize (``#ifdef __OPTIMIZE__``,
    ``macros.j2``): the library's part 1, at -O0, compiles that one, and a build
    whose ``$MODELGEN_CFLAGS`` ask for -O1 compiles the parts.  Both are the same
    operations in the same order (the -O0 library's results are bitwise those
    of the parts at -O0 before the flat text existed); they differ in the last
    bit of a few entries only because gcc at -O0 takes libm's sin and cos, not
    ``mg_sin`` and ``mg_cos`` (``model.c.j2``)."""
    spec = spatial_chain(LARGE_CHAIN).spec()
    flat = modelgen.load(spec, tmp_path / "flat", force=True)
    source = (tmp_path / "flat" / f"{flat.name}.c").read_text()
    assert "#ifdef __OPTIMIZE__" in source and f"{flat.name}_mass_matrix_part0(" in source
    monkeypatch.setenv("MODELGEN_CFLAGS", "-O1")
    parts = modelgen.load(spec, tmp_path / "parts", force=True)
    part1 = [c for c in parts.manifest["compile_commands"] if "-DMG_PART=1" in c]
    assert not part1 or part1[0].split().index("-O1") > part1[0].split().index("-O0")
    rng = np.random.default_rng(12)
    for _ in range(3):
        q, qd = rng.uniform(-2, 2, flat.n), rng.uniform(-2, 2, flat.n)
        for query, args in (("mass_matrix", (q,)), ("velocity_terms", (q, qd)),
                            ("generalized_forces", (0.0, q, qd)), ("energy", (q, qd)),
                            ("body_poses", (q,))):
            a, b = getattr(flat, query)(*args), getattr(parts, query)(*args)
            assert np.abs(a - b).max() <= 1e-14 * np.abs(a).max(), query
            assert np.all(np.isfinite(a)) and np.any(a != 0), query
