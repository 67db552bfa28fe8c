"""``<name>_jacobian`` and ``<name>_linearize`` built on the analytical derivatives.

A joint tree's Jacobian comes from ``<name>_derivatives`` (RNEA's derivatives,
derive/rnea_partials.py) wherever that has fewer operations than forward mode
over the rhs (codegen/pipeline.py ``_state_derivatives``).  Checked here against
central differences of the compiled rhs, against forward mode on the same
model, and end to end: a stiff 50-link chain with joint springs under rodas
against an explicit integrator.
"""
from __future__ import annotations

import numpy as np
import pytest

import modelgen
from conftest import SUMMARY
from modelgen.codegen import pipeline, tree_derivatives
from modelgen.model.chains import spatial_chain


def sprung_chain(n: int, k: float = 2000.0, c: float = 5.0):
    """``spatial_chain(n)`` with a torsion spring (stiffness k, rest angle 0) and
    viscous damping c on every joint: a stiff chain."""
    m = spatial_chain(n)
    m.add_parameters({"k": k, "c": c})
    for i in range(1, n + 1):
        m.add_effect(f"spring{i}", "torsion_spring", coordinate=f"q{i}", stiffness="k")
    m.add_effect("damping", "joint_damping", coordinates=[f"q{i}" for i in range(1, n + 1)],
                 damping="c")
    return m


def central_differences(cm, x, h=1e-6):
    """d xdot / d x of the compiled rhs by central differences, column by column."""
    return np.column_stack([(cm.rhs(0.0, x + h * e) - cm.rhs(0.0, x - h * e)) / (2 * h)
                            for e in np.eye(cm.nx)])


def _relative(a, b):
    return float(np.max(np.abs(a - b)) / np.max(np.abs(b)))


def _forced(monkeypatch, method):
    """A monkeypatch context in which the pipeline chooses ``method``."""
    mp = monkeypatch.context()
    ctx = mp.__enter__()
    ctx.setattr(tree_derivatives, "FORWARD_JACOBIAN_MAX", 100)
    if method == "forward":
        ctx.setattr(tree_derivatives, "derivatives_operations", lambda d, nu: 10 ** 12)
    else:
        ctx.setattr(tree_derivatives, "jacobian_operations", lambda terms: 10 ** 12)
    return mp


@pytest.mark.slow
def test_stiff_50_link_chain_with_springs_runs_under_rodas_on_the_derived_jacobian(
        tmp_path):
    n = 50
    cm = modelgen.load(sprung_chain(n), tmp_path / "build", jacobian=True)
    assert cm.manifest["jacobian_method"] == "derivatives"
    assert modelgen.sim.integrate.jacobian_source(cm) == "symbolic"
    rng = np.random.default_rng(50)
    x0 = np.concatenate([rng.uniform(-0.3, 0.3, n), rng.uniform(-1, 1, n)])
    J, fd = cm.jac(0.0, x0), central_differences(cm, x0)
    assert _relative(J, fd) <= 1e-6
    # the springs give modes far faster than the time span (about 260 rad/s: 20
    # periods in it) beside the slow swing of the chain
    fastest = float(np.max(np.abs(np.linalg.eigvals(J))))
    assert fastest > 100.0
    t_span = (0.0, 0.5)
    stiff = cm.simulate(x0, t_span, method="rodas", rtol=1e-6, atol=1e-8)
    reference = cm.simulate(x0, t_span, method="dop853", rtol=1e-11, atol=1e-13)
    assert stiff.success and reference.success
    assert stiff.njev > 0
    gap = float(np.max(np.abs(stiff.y[:, -1] - reference.y[:, -1])))
    assert gap <= 1e-5
    SUMMARY.append(f"50-link sprung chain: jacobian vs central differences "
           f"{_relative(J, fd):.1e}; fastest mode {fastest:.0f} rad/s; rodas "
           f"{stiff.nfev} rhs, {stiff.njev} Jacobians, dop853 {reference.nfev} rhs; "
           f"final state gap {gap:.1e}")


def test_jacobian_and_linearization_from_derivatives_match_forward_mode(tmp_path, monkeypatch):
    # the same model both ways: the choice forced, the numbers the same
    spec = sprung_chain(4).spec()
    built = {}
    for method in ("forward", "derivatives"):
        mp = _forced(monkeypatch, method)
        try:
            built[method] = modelgen.load(spec, tmp_path / method, linearize=True)
        finally:
            mp.__exit__(None, None, None)
        assert built[method].manifest["jacobian_method"] == method
    rng = np.random.default_rng(4)
    x = np.concatenate([rng.uniform(-1, 1, 4), rng.uniform(-1, 1, 4)])
    f, d = built["forward"], built["derivatives"]
    assert _relative(d.jac(0.0, x), f.jac(0.0, x)) <= 1e-12
    assert _relative(d.jac(0.0, x), central_differences(d, x)) <= 1e-7
    lf, ld = f.linearize(x), d.linearize(x)
    assert _relative(ld.A, lf.A) <= 1e-12
    # and what equilibrium finds from the derivatives' Jacobian: the springs' rest
    q = d.equilibrium(rng.uniform(-0.2, 0.2, 4))
    assert np.max(np.abs(d.rhs(0.0, np.concatenate([q, np.zeros(4)]))[4:])) <= 1e-10
    assert np.allclose(q, f.equilibrium(q + 0.01), atol=1e-8)


def test_linearization_with_inputs_and_outputs_from_derivatives(tmp_path, monkeypatch):
    # B from dqdd/du, C and D from the outputs' own forward mode: a scene with an
    # input and outputs built both ways gives the same A, B, C, D, and the C of
    # the derivatives' branch compiles strictly as C99 and as C++
    import subprocess
    from modelgen.model.scene import load_scene
    from modelgen.sim.runtime import CompiledModel
    from conftest import SCENES
    scene = load_scene(SCENES / "cart_pole_push.yaml")
    models = {}
    for method in ("forward", "derivatives"):
        mp = _forced(monkeypatch, method)
        try:
            g = pipeline.generate(scene.model, tmp_path / method, outputs=scene.outputs,
                                  linearize=True)
        finally:
            mp.__exit__(None, None, None)
        assert g.manifest["jacobian_method"] == method
        models[method] = (CompiledModel(g.manifest, g.build.module_path), g.build.directory)
    (f, _), (d, directory) = models["forward"], models["derivatives"]
    assert d.inputs and d.output_columns
    x, u = np.array([0.2, -0.3, 0.5, 0.7]), np.array([1.5])
    lf, ld = f.linearize(x, u, t=0.25), d.linearize(x, u, t=0.25)
    for a, b in ((ld.A, lf.A), (ld.B, lf.B), (ld.C, lf.C), (ld.D, lf.D)):
        assert a.shape == b.shape and _relative(a, b) <= 1e-12
    source = directory / f"{d.name}.c"
    for cmd in (["cc", "-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic"],
                ["c++", "-x", "c++", "-std=c++11", "-Wall", "-Wextra", "-Werror"]):
        r = subprocess.run(cmd + ["-c", str(source), "-I", str(directory), "-o",
                                  str(tmp_path / "out.o")], capture_output=True, text=True)
        assert r.returncode == 0, r.stderr


def test_generate_reports_the_jacobian_method_chosen_by_size(tmp_path, capsys):
    from modelgen.cli import main
    from conftest import MODELS
    said = {}
    for model in ("double_pendulum", "arm7"):
        assert main(["generate", str(MODELS / f"{model}.yaml"), "--jacobian",
                     "-o", str(tmp_path / model)]) == 0
        said[model] = next(line for line in capsys.readouterr().out.splitlines()
                           if line.startswith("jacobian"))
    # two dofs: forward mode has fewer operations; seven: the derivatives
    assert "forward mode" in said["double_pendulum"]
    assert "analytical derivatives" in said["arm7"]


def test_fmu_with_rodas_steps_on_the_derivatives_jacobian(tmp_path):
    # an implicit Co-Simulation method makes the export build the Jacobian; on the
    # 7-joint arm that is the derivatives', and the FMU's run agrees with simulate
    pytest.importorskip("fmpy")
    from fmpy import simulate_fmu
    from conftest import MODELS
    from modelgen.codegen.fmu import build_fmu
    fmu = build_fmu(MODELS / "arm7.yaml", tmp_path / "arm7.fmu", method="rodas",
                    rtol=1e-9, atol=1e-11, out_dir=tmp_path / "build")
    import zipfile
    with zipfile.ZipFile(fmu.path) as z:
        c = z.read("sources/arm7.c").decode()
    assert "arm7_derivatives(t, x, u, p, dq, dv" in c     # inside arm7_jacobian
    start = {"q2": 0.5, "q4": -1.0, "q6": 0.5}
    result = simulate_fmu(str(fmu.path), fmi_type="CoSimulation", start_time=0.0,
                          stop_time=1.0, output_interval=0.05, start_values=start,
                          output=list(fmu.names("local")))
    cm = modelgen.load(MODELS / "arm7.yaml", tmp_path / "build")
    x0 = [start.get(s, 0.0) for s in cm.state_names]
    res = cm.simulate(x0, (0.0, 1.0), t_eval=result["time"], rtol=1e-12, atol=1e-12)
    dev = max(float(np.max(np.abs(result[s] - res.y[k])))
              for k, s in enumerate(cm.state_names))
    SUMMARY.append(f"fmu arm7 rodas (derivatives' Jacobian): max |deviation| {dev:.1e}")
    assert dev <= 1e-6
