"""The generated C embedded in someone else's program: several output directories
in one program, headers of two modelgen versions, C++, sanitizers, threads, the
example's Makefile, and clang.

* Every top-level ``.c`` of three output directories (double pendulum, the free
  body of ``tennis_racket`` with its quaternion, the closed loop of ``four_bar``)
  compiles and links into one program: each directory carries its own copy of
  ``mg_integrate.c``, and on ELF and Mach-O those copies are weak definitions
  whose link names carry the ABI version, so one is kept; copies of two ABI
  versions link side by side, each model calling its own.  ``nm`` shows that
  every defined global carries a model's prefix or ``mg_``.
* A translation unit that includes headers of two ABI versions stops with an
  ``#error`` (the first ``mg_integrate.h`` wins its include guard, so the second
  model would be compiled against the other's structs).
* The same program under ASan and UBSan with work arrays allocated at exactly
  the documented size (every method, ``MG_MAX_EVENTS`` events, sampled and
  feedback inputs, a batch), three threads at once giving the bits of a
  sequential run, and valgrind when it is installed.
* ``mg_integrate_batch`` with ``p = NULL`` for a system without parameters (which
  its documentation allows) computes no ``NULL + 0`` (clang's UBSan).
* ``make generate run`` in one command builds the example.
* clang ``-Wall -Werror`` compiles a model without sin or cos (skipped without
  clang; a known failure of ``model.c.j2``, see the test).
"""
from __future__ import annotations

import concurrent.futures
import math
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

import modelgen

ROOT = Path(__file__).resolve().parent.parent
MODELS = ROOT / "models"
EXAMPLE = ROOT / "examples" / "embedded_c"
#: the models of the shared program: no constraint, a free joint, a closed loop
NAMES = ("double_pendulum", "tennis_racket", "four_bar")
C99 = ("cc", "-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic")
#: initial states (four_bar's is brought onto its loop by four_bar_constrain)
STATES = {"double_pendulum": "-0.5, 0.5, 0.0, 0.0",
          "tennis_racket": "0, 0, 0, 1, 0, 0, 0, 0, 0, 0, 0.01, 1.0, 0.01",
          "four_bar": "1.5, 0.5, 1.9, 1.0, 0.0, 0.0"}


def _run(cmd, cwd=None, timeout=300, env=None) -> subprocess.CompletedProcess:
    return subprocess.run([str(c) for c in cmd], cwd=cwd, timeout=timeout, env=env,
                          stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)


def _ok(cmd, cwd=None, **kw) -> str:
    r = _run(cmd, cwd, **kw)
    assert r.returncode == 0, f"$ {' '.join(map(str, cmd))}\n{r.stdout}"
    return r.stdout


@pytest.fixture(scope="module")
def dirs(tmp_path_factory) -> dict:
    """Output directories of NAMES, generated once for this module."""
    root = tmp_path_factory.mktemp("embedded")
    out = {}
    for name in NAMES:
        modelgen.generate_model(MODELS / f"{name}.yaml", root / name)
        out[name] = root / name
    return out


def _top_level_c(directory: Path) -> list:
    return sorted(directory.glob("*.c"))


def _compile_all(commands) -> None:
    """Run compile commands in parallel; fail with the output of those that failed."""
    with concurrent.futures.ThreadPoolExecutor(max(2, os.cpu_count() or 2)) as pool:
        results = list(pool.map(lambda cmd: (cmd, _run(cmd)), commands))
    failed = [f"$ {' '.join(map(str, c))}\n{r.stdout}" for c, r in results if r.returncode]
    assert not failed, "\n".join(failed)


def _objects(directories, out: Path, flags=()) -> list:
    """Every top-level .c of ``directories``, compiled (C99 -Werror) into ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    sources = [c for d in directories for c in _top_level_c(d)]
    objects = [out / f"{c.parent.name}_{c.stem}.o" for c in sources]
    _compile_all([[*C99, *flags, "-c", c, "-o", o] for c, o in zip(sources, objects)])
    return objects


@pytest.fixture(scope="module")
def objects(dirs, tmp_path_factory) -> list:
    """The output directories' C files at -O1, compiled once for this module."""
    return _objects(dirs.values(), tmp_path_factory.mktemp("objects"), ("-O1",))


# -- the program: every method of every model, exact-size work, threads -----------

_PROGRAM_HEAD = r"""
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
@INCLUDES@

typedef int (*integrate_fn)(double, double, const double *, const double *, const mg_inputs *,
                            const mg_options *, mg_output *, mg_stats *, double *);
typedef int (*batch_fn)(long, double, double, const double *, const double *, long,
                        const mg_inputs *, const mg_options *, long, const double *, double *,
                        double *, long *, int *, mg_stats *, double *, double *);
typedef struct {
    const char *name;
    int nx, nu;
    long work_size; /* the header's <NAME>_WORK_SIZE */
    integrate_fn integrate;
    batch_fn batch;
    void (*defaults)(double *);
    double x0[16];
} model;

#define MODEL(pfx, PFX) {#pfx, PFX##_NX, PFX##_NU, PFX##_WORK_SIZE, pfx##_integrate, \
                         pfx##_integrate_batch, pfx##_default_parameters, {0}}
static model models[] = {@MODELS@};
#define NMODELS ((int)(sizeof models / sizeof models[0]))
#define NOUT (MG_METHOD_GAUSS4 + 3)

static int events_g(void *ctx, double t, const double *x, double *g)
{
    int k;
    (void)ctx; (void)x;
    for (k = 0; k < MG_MAX_EVENTS; ++k) g[k] = t - 0.25 - 0.001 * k;
    return 0;
}

static int feedback(void *ctx, double t, const double *x, double *u)
{
    const model *m = (const model *)ctx;
    int i;
    for (i = 0; i < m->nu; ++i) u[i] = -0.1 * x[0] + 0.01 * t;
    return 0;
}

/* A heap array of exactly n doubles (ASan flags a read or write past it). */
static double *exact(long n)
{
    return (double *)malloc(sizeof(double) * (size_t)(n > 0 ? n : 1));
}
"""

_PROGRAM_RUN = r"""
/* One run of method on m into out[nx]; with_events: MG_MAX_EVENTS events and the
 * header's work size, else mg_work_size(nx, nu, 0); inputs sampled or fed back. */
static int run_one(const model *m, int method, int with_events, int feedback_inputs, double *out)
{
    static const double times[2] = {0.0, 1.0};
    double p[32], tol[16], stop[MG_STOP_X + 16], t_end = 0.5, values[2 * 8];
    double te[2 * MG_MAX_EVENTS], xe[2 * MG_MAX_EVENTS * 16];
    int which[2 * MG_MAX_EVENTS], both[MG_MAX_EVENTS] = {0}, i, status;
    double *work = exact(with_events ? m->work_size : mg_work_size(m->nx, m->nu, 0));
    mg_options o; mg_output y; mg_stats s; mg_inputs in;
    memset(&o, 0, sizeof o); memset(&y, 0, sizeof y); memset(&in, 0, sizeof in);
    for (i = 0; i < m->nx; ++i) tol[i] = 1e-9;
    for (i = 0; i < 2 * 8; ++i) values[i] = 0.1 * i;
    m->defaults(p);
    o.method = method; o.rtol = tol; o.atol = tol; o.max_steps = 100000;
    if (method == MG_METHOD_RK4 || method == MG_METHOD_MIDPOINT || method == MG_METHOD_GAUSS4)
        o.fixed_step = 1e-3;
    if (with_events) {
        o.n_events = MG_MAX_EVENTS; o.events = events_g; o.direction = both; o.terminal = both;
        y.events_capacity = 2 * MG_MAX_EVENTS; y.t_events = te; y.x_events = xe;
        y.which_events = which;
    }
    if (m->nu > 0 && feedback_inputs) { in.callback = feedback; in.ctx = (void *)m; }
    if (m->nu > 0 && !feedback_inputs) { in.n = 2; in.times = times; in.values = values; }
    y.capacity = 1; y.t_eval = &t_end; y.x = out; y.stop = stop;
    status = m->integrate(0.0, t_end, m->x0, p, &in, &o, &y, &s, work);
    free(work);
    if (status != MG_STATUS_SUCCESS || (with_events && y.n_events != MG_MAX_EVENTS)) {
        printf("%s method %d: status %d, %ld events\n", m->name, method, status, y.n_events);
        return 1;
    }
    return 0;
}

/* Three runs of a batch, each into out[nx] in turn (they must agree). */
static int run_batch(const model *m, double *out)
{
    double p[32], tol[16], t_end = 0.5, *x0 = exact(3 * m->nx), *xo = exact(3 * m->nx);
    double *st = exact(3 * (MG_STOP_X + m->nx)), *work = exact(mg_work_size(m->nx, m->nu, 0));
    long n_out[3];
    int status[3], i, failures;
    mg_stats s[3]; mg_options o;
    memset(&o, 0, sizeof o);
    for (i = 0; i < m->nx; ++i) tol[i] = 1e-9;
    m->defaults(p);
    o.method = MG_METHOD_DOPRI5; o.rtol = tol; o.atol = tol; o.max_steps = 100000;
    for (i = 0; i < 3; ++i) memcpy(x0 + i * m->nx, m->x0, sizeof(double) * (size_t)m->nx);
    failures = m->batch(3, 0.0, t_end, x0, p, 0, NULL, &o, 1, &t_end, xo, NULL, n_out, status, s,
                        st, work) != 0;
    failures += memcmp(xo, xo + m->nx, sizeof(double) * (size_t)m->nx) != 0;
    memcpy(out, xo + 2 * m->nx, sizeof(double) * (size_t)m->nx);
    free(x0); free(xo); free(st); free(work);
    if (failures) printf("%s: batch failed\n", m->name);
    return failures;
}

typedef struct { double out[8][NOUT][16]; int failures; } result;

static void *run_all(void *arg)
{
    result *r = (result *)arg;
    int k, method;
    for (k = 0; k < NMODELS; ++k) {
        for (method = 0; method <= MG_METHOD_GAUSS4; ++method)
            r->failures += run_one(&models[k], method, 0, method == MG_METHOD_RODAS,
                                   r->out[k][method]);
        r->failures += run_one(&models[k], MG_METHOD_DOP853, 1, 0, r->out[k][NOUT - 2]);
        r->failures += run_batch(&models[k], r->out[k][NOUT - 1]);
    }
    return NULL;
}

int main(int argc, char **argv)
{
    static result sequential, parallel[3];
    pthread_t threads[3];
    int k, n_threads = argc > 1 ? atoi(argv[1]) : 0, failures;
@SETUP@
    run_all(&sequential);
    failures = sequential.failures;
    for (k = 0; k < n_threads; ++k) pthread_create(&threads[k], NULL, run_all, &parallel[k]);
    for (k = 0; k < n_threads; ++k) {
        pthread_join(threads[k], NULL);
        failures += parallel[k].failures;
        if (memcmp(parallel[k].out, sequential.out, sizeof sequential.out) != 0) {
            printf("thread %d differs from the sequential run\n", k);
            ++failures;
        }
    }
    printf("failures: %d\n", failures);
    return failures != 0;
}
"""


def _program(names) -> str:
    setup = []
    for k, name in enumerate(names):
        setup.append(f"    {{ const double x0[] = {{{STATES[name]}}};\n"
                     f"      memcpy(models[{k}].x0, x0, sizeof x0); }}")
        if name == "four_bar":
            setup.append(f"    {{ double p[FOUR_BAR_NP]; four_bar_default_parameters(p);\n"
                         f"      if (four_bar_constrain(p, models[{k}].x0)) return 1; }}")
    fill = {"@INCLUDES@": "\n".join(f'#include "{n}.h"' for n in names),
            "@MODELS@": ", ".join(f"MODEL({n}, {n.upper()})" for n in names),
            "@SETUP@": "\n".join(setup)}
    text = _PROGRAM_HEAD + _PROGRAM_RUN
    for key, value in fill.items():
        text = text.replace(key, value)
    return text


def _build_program(dirs: dict, out: Path, objects=None, flags=(), exe="program") -> Path:
    """main.c linked with every top-level .c of every output directory (``objects``,
    else compiled here with ``flags``)."""
    out.mkdir(exist_ok=True)
    (out / "main.c").write_text(_program(list(dirs)))
    if objects is None:
        objects = _objects(dirs.values(), out, flags)
    _ok([*C99, *flags, *(f"-I{d}" for d in dirs.values()), "-c", out / "main.c", "-o",
         out / "main.o"])
    _ok(["cc", *flags, out / "main.o", *objects, "-o", out / exe, "-lm", "-lpthread"])
    return out / exe


def _defined_globals(obj: Path) -> list:
    return [line.split()[-1] for line in _ok(["nm", "-g", "--defined-only", obj]).splitlines()
            if line.strip()]


def test_every_c_file_of_three_output_directories_links_into_one_program(dirs, objects,
                                                                          tmp_path):
    """Compiling every top-level .c of each output directory (as the example's
    README says to do with one) links: the three copies of mg_integrate.c used to
    define mg_integrate, mg_integrate_batch, mg_jacobian_fd and mg_work_size three
    times ("multiple definition").  The program then integrates each model with
    every method; every global it defines carries a model's prefix or mg_."""
    binary = _build_program(dirs, tmp_path, objects)
    assert "failures: 0" in _ok([binary])
    for obj in objects:
        for symbol in _defined_globals(obj):
            assert symbol.startswith(tuple(f"{n}_" for n in NAMES) + ("mg_",)), (obj, symbol)


def _with_abi(source: Path, target: Path, abi: int) -> Path:
    """A copy of output directory ``source`` as another modelgen version with
    ABI ``abi`` would write it (the version numbers of its two headers)."""
    shutil.copytree(source, target)
    for header in target.glob("*.h"):
        text = re.sub(r"(_ABI_VERSION) \d+\b", rf"\1 {abi}", header.read_text())
        text = re.sub(r"\b(mg_\w+_abi)\d+\b", rf"\g<1>{abi}", text)   # the link names
        header.write_text(text)
    return target


def test_integrators_of_two_abi_versions_link_side_by_side(dirs, objects, tmp_path):
    """Output directories of two modelgen versions whose interfaces differ, each
    model compiled in a translation unit of its own: both copies of the
    integrators are kept (their link names carry the ABI version), so each model
    calls the integrators of its own structs; before, they clashed, and one copy
    compiled once would have served the other model's structs."""
    abi = int(re.search(r"MG_ABI_VERSION (\d+)", (dirs["double_pendulum"] /
                                                  "mg_integrate.h").read_text())[1])
    other = _with_abi(dirs["tennis_racket"], tmp_path / "tennis_racket", abi + 1)
    units = {"a.c": ("double_pendulum", dirs["double_pendulum"], "int run_b(void);\nint main(void)"),
             "b.c": ("tennis_racket", other, "int run_b(void)")}
    linked = []
    for unit, (name, directory, head) in units.items():
        n = name.upper()
        (tmp_path / unit).write_text(
            f'#include <stdio.h>\n#include <string.h>\n#include "{name}.h"\n{head}\n{{\n'
            f"    double p[{n}_NP], x[{n}_NX] = {{{STATES[name]}}}, x1[{n}_NX], tol[{n}_NX];\n"
            f"    double stop[MG_STOP_X + {n}_NX], work[{n}_WORK_SIZE], t = 0.5;\n"
            "    mg_options o; mg_output y; mg_stats s; int i, status;\n"
            "    memset(&o, 0, sizeof o); memset(&y, 0, sizeof y);\n"
            f"    for (i = 0; i < {n}_NX; ++i) tol[i] = 1e-9;\n"
            f"    {name}_default_parameters(p);\n"
            "    o.method = MG_METHOD_DOP853; o.rtol = tol; o.atol = tol; o.max_steps = 10000;\n"
            "    y.capacity = 1; y.t_eval = &t; y.x = x1; y.stop = stop;\n"
            f"    status = {name}_integrate(0.0, t, x, p, NULL, &o, &y, &s, work);\n"
            + ("    status += run_b();\n" if unit == "a.c" else "")
            + f'    printf("{name} %d %ld\\n", status, s.naccept);\n'
            "    return status;\n}\n")
        linked.append(tmp_path / f"{unit}.o")
        _ok([*C99, f"-I{directory}", "-c", tmp_path / unit, "-o", linked[-1]])
    linked += [o for o in objects if o.name.startswith("double_pendulum_")]
    linked += _objects([other], tmp_path / "other", ("-O1",))
    _ok(["cc", *linked, "-o", tmp_path / "two_abis", "-lm"])
    output = _ok([tmp_path / "two_abis"])
    assert re.search(r"tennis_racket 0 [1-9]", output) and re.search(r"double_pendulum 0 [1-9]",
                                                                      output), output
    defined = {s for o in linked for s in _defined_globals(o)}
    assert {f"mg_integrate_abi{abi}", f"mg_integrate_abi{abi + 1}"} <= defined, sorted(defined)


def test_headers_of_two_abi_versions_refuse_one_translation_unit(dirs, tmp_path):
    """The first mg_integrate.h included wins its include guard: a second model's
    header from another ABI version would declare its functions with the other's
    structs.  Its header stops the compile with an #error that says so."""
    other = _with_abi(dirs["tennis_racket"], tmp_path / "tennis_racket", 1000)
    (tmp_path / "both.c").write_text('#include "double_pendulum.h"\n#include "tennis_racket.h"\n'
                                     "int main(void) { return 0; }\n")
    r = _run([*C99, f"-I{dirs['double_pendulum']}", f"-I{other}", "-c", tmp_path / "both.c",
              "-o", tmp_path / "both.o"])
    assert r.returncode != 0 and "ABI" in r.stdout, r.stdout
    # each header alone, or two of one version, compile
    _ok([*C99, f"-I{other}", "-x", "c", "-c", other / "tennis_racket.h", "-o", tmp_path / "t.o"])
    (tmp_path / "same.c").write_text('#include "double_pendulum.h"\n#include "four_bar.h"\n'
                                     "int main(void) { return 0; }\n")
    _ok([*C99, f"-I{dirs['double_pendulum']}", f"-I{dirs['four_bar']}", "-c",
         tmp_path / "same.c", "-o", tmp_path / "same.o"])


def test_the_headers_serve_cxx17(dirs, objects, tmp_path):
    """g++ -std=c++17 -pedantic: three models' headers in one translation unit, their
    functions called and linked against the C objects (extern "C")."""
    (tmp_path / "main.cpp").write_text(_program(list(dirs)))
    includes = [f"-I{d}" for d in dirs.values()]
    _ok(["c++", "-x", "c++", "-std=c++17", "-Wall", "-Wextra", "-Werror", "-pedantic", *includes,
         "-c", tmp_path / "main.cpp", "-o", tmp_path / "main.o"])
    _ok(["c++", tmp_path / "main.o", *objects, "-o", tmp_path / "cxx", "-lm", "-lpthread"])
    assert "failures: 0" in _ok([tmp_path / "cxx"])


def _sanitizers_work(cc: str) -> bool:
    probe = Path(os.environ.get("TMPDIR", "/tmp"))
    r = subprocess.run([cc, "-fsanitize=address,undefined", "-x", "c", "-", "-o", os.devnull],
                       input="int main(void) { return 0; }\n", text=True, cwd=probe,
                       stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    return r.returncode == 0


@pytest.mark.slow
@pytest.mark.skipif(not shutil.which("cc") or not _sanitizers_work("cc"),
                    reason="cc without ASan/UBSan")
def test_three_models_under_sanitizers_with_exact_work_arrays_and_threads(dirs, objects,
                                                                          tmp_path):
    """ASan + UBSan (every finding fatal): each model with every method, the
    header's WORK_SIZE (MG_MAX_EVENTS events, all found) and mg_work_size(nx, nu, 0)
    as exact heap arrays, sampled and feedback inputs, a batch; then three threads
    at once, whose results are the sequential run's bits (no shared mutable state),
    and the plain build under valgrind when it is installed."""
    flags = ("-O1", "-g", "-fsanitize=address,undefined", "-fno-sanitize-recover=all",
             "-fno-omit-frame-pointer")
    binary = _build_program(dirs, tmp_path / "asan", flags=flags)
    env = dict(os.environ, ASAN_OPTIONS="detect_leaks=1:abort_on_error=0")
    assert "failures: 0" in _ok([binary, 3], env=env)
    if shutil.which("valgrind"):
        plain = _build_program(dirs, tmp_path / "plain", objects)
        _ok(["valgrind", "-q", "--error-exitcode=9", "--leak-check=full", plain, 2])


C_ONLY_BATCH = r"""
#include <stdio.h>
#include <string.h>
#include "mg_integrate.h"
static int decay(void *m, double t, const double *x, const double *u, const double *p, double *out)
{
    (void)m; (void)t; (void)u; (void)p;
    out[0] = -x[0];
    return 0;
}
int main(void)
{
    mg_system s; mg_options o;
    double x0[2] = {1.0, 2.0}, t1 = 1.0, x1[2], stop[2 * (MG_STOP_X + 1)], tol = 1e-10;
    double work[MG_WORK_SIZE(1, 0, 0)];
    long n_out[2]; int status[2], failed; mg_stats stats[2];
    memset(&s, 0, sizeof s); memset(&o, 0, sizeof o);
    s.nx = 1; s.rhs = decay;   /* np = 0: p may be NULL */
    o.method = MG_METHOD_DOP853; o.rtol = &tol; o.atol = &tol; o.max_steps = 1000;
    failed = mg_integrate_batch(&s, 2, 0.0, t1, x0, NULL, 0, NULL, &o, 1, &t1, x1, NULL, n_out,
                                status, stats, stop, work);
    printf("%d %.12f %.12f\n", failed, x1[0], x1[1]);
    return failed;
}
"""


@pytest.mark.skipif(not shutil.which("clang") or not _sanitizers_work("clang"),
                    reason="clang (whose UBSan reports NULL + 0) is not installed")
def test_a_batch_without_parameters_takes_p_null_without_undefined_behaviour(dirs, tmp_path):
    """mg_integrate_batch's documentation allows p = NULL when np = 0; it computed
    p + r * p_stride, NULL + 0, undefined in C (clang: "applying zero offset to
    null pointer")."""
    (tmp_path / "batch.c").write_text(C_ONLY_BATCH)
    d = dirs["double_pendulum"]
    _ok(["clang", "-std=c99", "-g", "-fsanitize=address,undefined", "-fno-sanitize-recover=all",
         f"-I{d}", tmp_path / "batch.c", d / "mg_integrate.c", "-o", tmp_path / "batch", "-lm"])
    failed, x1, x2 = map(float, _ok([tmp_path / "batch"]).split())
    assert failed == 0 and x1 == pytest.approx(math.exp(-1), rel=1e-8)
    assert x2 == pytest.approx(2 * math.exp(-1), rel=1e-8)


def test_the_examples_generate_and_run_targets_work_in_one_command(tmp_path):
    """``make generate run`` from nothing: the Makefile listed the model's sources
    with $(wildcard) when it was read, before generate had written them, and the
    link failed with undefined references."""
    model_dir, build = tmp_path / "model", tmp_path / "build"
    r = _run(["make", "-C", EXAMPLE, "generate", "run", f"PYTHON={sys.executable}",
              f"MODEL_DIR={model_dir}", f"BUILD_DIR={build}"])
    assert r.returncode == 0, r.stdout
    assert "energy drift:" in r.stdout
    # built already: nothing to do; without a model: what to run instead
    r = _run(["make", "-C", EXAMPLE, f"MODEL_DIR={model_dir}", f"BUILD_DIR={build}"])
    assert r.returncode == 0 and "cc " not in r.stdout, r.stdout
    r = _run(["make", "-C", EXAMPLE, f"MODEL_DIR={tmp_path / 'none'}", f"BUILD_DIR={build}"])
    assert r.returncode != 0 and "make generate" in r.stdout, r.stdout


@pytest.mark.skipif(not shutil.which("clang"), reason="clang is not installed")
def test_clang_compiles_a_model_without_sin_or_cos_with_werror(dirs, tmp_path):
    """tennis_racket (a quaternion, no angle) at -O2: mg_sin and mg_cos are unused,
    and so are some kernels in one part of a model's file (MG_PART, as the build
    compiles it).  That broke ``CC=clang modelgen generate models/tennis_racket.yaml``,
    whose build compiles with -Werror."""
    for name in ("tennis_racket", "double_pendulum", "four_bar"):
        source = dirs[name] / f"{name}.c"
        for part in ([], *([f"-DMG_PART={k}"] for k in range(1, 5))):
            _ok(["clang", "-std=c99", "-Wall", "-Wextra", "-Werror", "-O2", *part, "-c",
                 source, "-o", tmp_path / "t.o"])
