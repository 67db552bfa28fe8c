"""URDF import: the models of real robots against Pinocchio, and the importer's errors.

The URDFs in tests/data/urdf are copied from the ``example-robot-data``
package (licences in tests/data/urdf/README.md).  The comparisons with
Pinocchio (``pip install -e '.[robots]'``) are skipped when it is missing;
the other tests always run.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import sympy
import pytest

from modelgen.cli import main
from modelgen.errors import ModelError
from modelgen.model import as_spec, load_model
from modelgen.model.spec import symbol
from modelgen.model.urdf import import_urdf, import_urdf_text, sanitize, urdf_to_yaml
from modelgen.sim.load import load

DATA = Path(__file__).parent / "data" / "urdf"
#: relative (max-norm, over max(1, max |reference|) or max |A|) against Pinocchio;
#: measured worst 1.6e-14 (the exotic robot's q_ddot), 4.2e-14 with a floating joint
TOL = 1e-12
#: q_ddot of solo12 by crba: its A has cond about 2e4 (light legs on the body), and
#: the Cholesky's rounding grows with it (measured 8.8e-13; Pinocchio's ABA and numpy's
#: solve of the same A differ from each other by 6e-13 too); by aba, 2.7e-15
SOLO12_CRBA_QDD_TOL = 1e-11

#: a synthetic robot with everything the real ones lack: rpy about all three
#: axes, axes along no base axis (revolute and prismatic), negative axes, an
#: inertial with its own rpy, a welded child with mass, a massless link in the
#: chain, a mimic with multiplier and offset, branches and damping.
EXOTIC = """<?xml version="1.0"?>
<robot name="exotic">
  <link name="world"/>
  <link name="a"><inertial><origin xyz="0.1 -0.05 0.2" rpy="0.3 -0.2 0.5"/><mass value="2.0"/>
    <inertia ixx="0.05" ixy="0.004" ixz="-0.003" iyy="0.04" iyz="0.002" izz="0.03"/></inertial></link>
  <link name="b"><inertial><origin xyz="0.0 0.2 0.1" rpy="-0.4 0.1 0.2"/><mass value="1.5"/>
    <inertia ixx="0.02" ixy="0.001" ixz="0.0" iyy="0.03" iyz="-0.002" izz="0.025"/></inertial></link>
  <link name="tool"><inertial><origin xyz="0.05 0.0 -0.02" rpy="0.7 0.0 -0.3"/><mass value="0.7"/>
    <inertia ixx="0.004" ixy="0.0" ixz="0.0005" iyy="0.005" iyz="0.0" izz="0.006"/></inertial></link>
  <link name="frame_only"/>
  <link name="c"><inertial><mass value="0.9"/>
    <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.012" iyz="0" izz="0.008"/></inertial></link>
  <link name="d"><inertial><origin xyz="0.02 0.03 0.04"/><mass value="0.4"/>
    <inertia ixx="0.002" ixy="0" ixz="0" iyy="0.002" iyz="0" izz="0.001"/></inertial></link>
  <link name="e"><inertial><origin xyz="0.0 0.0 0.05"/><mass value="0.3"/>
    <inertia ixx="0.001" ixy="0" ixz="0" iyy="0.001" iyz="0" izz="0.0005"/></inertial></link>
  <joint name="j1" type="revolute"><parent link="world"/><child link="a"/>
    <origin xyz="0.1 0.2 0.3" rpy="0.1 0.2 0.3"/><axis xyz="0.2 -0.5 0.8"/>
    <limit lower="-2" upper="2" effort="10" velocity="1"/><dynamics damping="0.2"/></joint>
  <joint name="j2-slide" type="prismatic"><parent link="a"/><child link="b"/>
    <origin xyz="0.0 0.4 0.0" rpy="-0.3 0.5 1.2"/><axis xyz="0.6 0.0 -0.8"/>
    <limit lower="-1" upper="1" effort="50" velocity="1"/></joint>
  <joint name="weld" type="fixed"><parent link="b"/><child link="tool"/>
    <origin xyz="0.1 0.0 0.3" rpy="1.0 -0.4 0.25"/></joint>
  <joint name="to_frame" type="fixed"><parent link="tool"/><child link="frame_only"/>
    <origin xyz="0.0 0.1 0.0" rpy="0 0 1.5707963"/></joint>
  <joint name="j3" type="continuous"><parent link="frame_only"/><child link="c"/>
    <origin xyz="0.05 0.0 0.1"/><axis xyz="0 -1 0"/></joint>
  <joint name="j4" type="revolute"><parent link="a"/><child link="d"/>
    <origin xyz="-0.2 0.0 0.1" rpy="0 0.3 0"/><axis xyz="1 0 0"/>
    <limit lower="-1" upper="1" effort="5" velocity="1"/></joint>
  <joint name="j5" type="revolute"><parent link="d"/><child link="e"/>
    <origin xyz="0.0 0.1 0.0"/><axis xyz="0 0 -1"/>
    <limit lower="-1" upper="1" effort="5" velocity="1"/><mimic joint="j4" multiplier="-0.7" offset="0.25"/></joint>
</robot>
"""


def _pinocchio_maps(pm, imp):
    """q -> Pinocchio's configuration, and J (nv x n) with Pinocchio's v = J qd.

    Pinocchio orders sibling joints its own way and, built with mimic=False,
    keeps a mimic joint as a joint of its own: J maps through the mimic law.
    """
    joints = {j.name: j for j in imp.joints}
    index = {c: k for k, c in enumerate(imp.model.spec().coordinates)}
    jmap = np.zeros((pm.nv, len(index)))
    parts = []
    for jid in range(1, pm.njoints):
        info = joints[pm.names[jid]]
        coordinate, mult, off = (info.coordinate, 1.0, 0.0) if info.mimic is None \
            else info.mimic
        jmap[pm.joints[jid].idx_v, index[coordinate]] = mult
        parts.append((pm.joints[jid].idx_q, pm.joints[jid].nq, index[coordinate], mult, off))

    def q_of(q):
        out = np.zeros(pm.nq)
        for iq, nq, k, mult, off in parts:
            angle = mult * q[k] + off
            out[iq:iq + nq] = [math.cos(angle), math.sin(angle)] if nq == 2 else [angle]
        return out
    return q_of, jmap


def _compare_with_pinocchio(pin, path: Path, out_dir: Path, samples: int = 4) -> None:
    imp = import_urdf(path)
    cm = load(imp.model, out_dir)
    pm = pin.buildModelFromUrdf(str(path))
    pd = pm.createData()
    q_of, jmap = _pinocchio_maps(pm, imp)
    damping = np.array([j.damping for j in imp.joints if j.coordinate is not None])
    n = cm.n
    assert len(damping) == n
    rng = np.random.default_rng(20240611)
    for _ in range(samples):
        q, qd, u = rng.uniform(-1.5, 1.5, n), rng.uniform(-2, 2, n), rng.uniform(-5, 5, n)
        pq, pv = q_of(q), jmap @ qd
        m_pin = pin.crba(pm, pd, pq)
        m_pin = np.triu(m_pin) + np.triu(m_pin, 1).T
        a_ref = jmap.T @ m_pin @ jmap
        a_mg = cm.mass_matrix(q)
        assert np.max(np.abs(a_mg - a_ref)) <= TOL * np.max(np.abs(a_ref))
        # h - tau_gravity = Pinocchio's non-linear effects C v + g (gravity from qd = 0)
        nle = jmap.T @ pin.nonLinearEffects(pm, pd, pq, pv)
        tau_gravity = cm.generalized_forces(0.0, q, np.zeros(n), np.zeros(n))
        h_mg = cm.velocity_terms(q, qd) - tau_gravity
        assert np.max(np.abs(h_mg - nle)) <= TOL * max(1.0, np.max(np.abs(nle)))
        # the inputs are the joint efforts, the damping effects -c qd
        forces = cm.generalized_forces(0.0, q, qd, u) - tau_gravity
        assert np.max(np.abs(forces - (u - damping * qd))) <= TOL * np.max(np.abs(u))
        tau = u - damping * qd
        if pm.nv == n:
            qdd_ref = pin.aba(pm, pd, pq, pv, tau)
        else:           # mimic joints: the reduced equations from Pinocchio's CRBA and RNEA
            qdd_ref = np.linalg.solve(a_ref, tau - nle)
        qdd_mg = cm.rhs(0.0, np.concatenate([q, qd]), u)[n:]
        assert np.max(np.abs(qdd_mg - qdd_ref)) <= TOL * max(1.0, np.max(np.abs(qdd_ref)))
        # inverse dynamics: Pinocchio's rnea (M a + C v + g) is Q plus the model's other
        # forces (the inputs and the damping)
        acc = rng.uniform(-3, 3, n)
        rnea = jmap.T @ pin.rnea(pm, pd, pq, pv, jmap @ acc)
        Q = cm.inverse_dynamics(0.0, np.concatenate([q, qd]), acc, u)
        assert np.max(np.abs(Q + tau - rnea)) <= TOL * max(1.0, np.max(np.abs(rnea)))


@pytest.fixture(scope="module")
def pin():
    return pytest.importorskip("pinocchio")


@pytest.mark.parametrize("robot", ["double_pendulum", "ur5_robot", "panda", "kinova"])
def test_real_robots_match_pinocchio_crba_nle_aba(robot, pin, tmp_path):
    _compare_with_pinocchio(pin, DATA / f"{robot}.urdf", tmp_path / "build")


def test_unaligned_axes_rpy_welds_and_mimic_match_pinocchio(pin, tmp_path):
    path = tmp_path / "exotic.urdf"
    path.write_text(EXOTIC)
    _compare_with_pinocchio(pin, path, tmp_path / "build")


# -- floating bases and floating joints: free joints (a unit quaternion) ----------------

def _free_joint_names(joint: str) -> tuple:
    return (tuple(f"{joint}_{s}" for s in ("x", "y", "z", "qx", "qy", "qz", "qw")),
            tuple(f"{joint}_{s}" for s in ("vx", "vy", "vz", "wx", "wy", "wz")))


def _compare_floating_with_pinocchio(pin, imp, pm, cm, samples: int = 4,
                                     qdd_tol: float = TOL) -> float:
    """A, h - tau_gravity, the forces and q'' against Pinocchio with free joints:
    Pinocchio's q holds (x, y, z, qx, qy, qz, qw) per free joint (its free-flyer),
    modelgen's the simple coordinates first and each free joint's (x, y, z, qw, qx,
    qy, qz) last; the speeds (v in the joint's base, then w) are the same quantities,
    permuted.  The tau given to Pinocchio's aba is built from the URDF (each joint's
    effort input on its own speed, minus its damping times that speed; nothing on a
    free joint), not from modelgen's generalized forces."""
    pd = pm.createData()
    joints = {j.name: j for j in imp.joints}
    names, speeds = list(cm.coordinates), list(cm.speeds)
    P = np.zeros((pm.nv, cm.n))          # Pinocchio's v = P modelgen's v
    q_parts = []
    for jid in range(1, pm.njoints):
        jm, name = pm.joints[jid], pm.names[jid]
        info = joints.get(name)
        if info is None or info.type == "floating":       # root_joint, or a floating one
            qn, vn = _free_joint_names(sanitize(name))
            q_parts.append((jm.idx_q, [names.index(c) for c in qn], None))
            for k, v in enumerate(vn):
                P[jm.idx_v + k, speeds.index(v)] = 1.0
        else:
            q_parts.append((jm.idx_q, [names.index(info.coordinate)], jm.nq))
            P[jm.idx_v, speeds.index(info.coordinate + "_dot")] = 1.0
    assert np.all(P.sum(axis=0) == 1) and np.all(P.sum(axis=1) == 1)
    nu = len(cm.inputs)
    B, damping = np.zeros((cm.n, nu)), np.zeros(cm.n)    # tau = B u - damping * v
    for info in imp.joints:
        if info.coordinate is None or info.type == "floating":
            continue
        k = speeds.index(info.coordinate + "_dot")
        damping[k] = info.damping
        if info.input is not None:
            B[k, cm.inputs.index(info.input)] = 1.0
    assert np.all(B.sum(axis=0) == 1)        # every input is the effort of one joint

    def q_pin(q):
        out = np.zeros(pm.nq)
        for iq, ks, nq in q_parts:
            if nq is None:
                out[iq:iq + 7] = q[ks]
            else:
                out[iq:iq + nq] = [math.cos(q[ks[0]]), math.sin(q[ks[0]])] if nq == 2 \
                    else [q[ks[0]]]
        return out
    rng = np.random.default_rng(20261123)
    worst = 0.0
    for _ in range(samples):
        q = cm.project(rng.uniform(-1.5, 1.5, cm.nq))     # random unit quaternions
        v, u = rng.uniform(-2, 2, cm.n), rng.uniform(-5, 5, nu)
        pq, pv = q_pin(q), P @ v
        for iq, _, nq in q_parts:
            if nq is None:
                assert abs(np.linalg.norm(pq[iq + 3:iq + 7]) - 1) < 1e-15
        m_pin = pin.crba(pm, pd, pq)
        a_ref = P.T @ (np.triu(m_pin) + np.triu(m_pin, 1).T) @ P
        a_mg = cm.mass_matrix(q)
        nle = P.T @ pin.nonLinearEffects(pm, pd, pq, pv)
        tau_gravity = cm.generalized_forces(0.0, q, np.zeros(cm.n), np.zeros(nu))
        h_mg = cm.velocity_terms(q, v) - tau_gravity
        tau = B @ u - damping * v
        forces = cm.generalized_forces(0.0, q, v, u) - tau_gravity
        qdd_ref = P.T @ pin.aba(pm, pd, pq, pv, P @ tau)
        qdd_mg = cm.rhs(0.0, np.concatenate([q, v]), u)[cm.nq:]
        errors = (np.max(np.abs(a_mg - a_ref)) / np.max(np.abs(a_ref)),
                  np.max(np.abs(h_mg - nle)) / max(1.0, np.max(np.abs(nle))),
                  np.max(np.abs(forces - tau)) / max(1.0, np.max(np.abs(tau))))
        qdd_error = np.max(np.abs(qdd_mg - qdd_ref)) / max(1.0, np.max(np.abs(qdd_ref)))
        assert max(errors) <= TOL and qdd_error <= qdd_tol, (errors, qdd_error)
        worst = max(worst, *errors, qdd_error)
    return worst


def _installed_robot(relative: str) -> Path:
    pin = pytest.importorskip("pinocchio")
    share = Path(pin.__file__).resolve().parents[4] / "share" / "example-robot-data" / "robots"
    path = share / relative
    if not path.exists():
        pytest.skip(f"example-robot-data has no {relative} here ({share})")
    return path


@pytest.mark.parametrize("robot, formulation", [("solo12", "crba"), ("solo12", "aba"),
                                                ("go2", "auto")])
def test_floating_base_quadrupeds_match_pinocchio_free_flyer(robot, formulation, pin,
                                                             tmp_path):
    path = DATA / "solo12.urdf" if robot == "solo12" else \
        _installed_robot("go2_description/urdf/go2.urdf")
    imp = import_urdf(path, floating_base=True)
    spec = imp.model.spec()
    assert spec.nq == spec.n + 1 == 19
    assert spec.coordinates[-7:] == tuple(f"root_joint_{s}" for s in
                                          ("x", "y", "z", "qw", "qx", "qy", "qz"))
    cm = load(imp.model, tmp_path / "build", formulation=formulation)
    assert robot != "solo12" or len(cm.inputs) == 12    # the forces are compared too
    qdd_tol = SOLO12_CRBA_QDD_TOL if (robot, formulation) == ("solo12", "crba") else TOL
    _compare_floating_with_pinocchio(pin, imp, pin.buildModelFromUrdf(str(path),
                                                                       pin.JointModelFreeFlyer()),
                                     cm, qdd_tol=qdd_tol)


def test_a_floating_joint_inside_the_tree_matches_pinocchio(pin, tmp_path):
    """A URDF 'floating' joint between two links (a free body riding on an arm)."""
    text = EXOTIC.replace('<joint name="j3" type="continuous">',
                          '<joint name="j3" type="floating">')
    text = text.replace('<mimic joint="j4" multiplier="-0.7" offset="0.25"/>', "")
    path = tmp_path / "floating.urdf"
    path.write_text(text)
    imp = import_urdf(path)
    assert "j3" not in imp.model.spec().coordinates and "j3_qw" in imp.model.spec().coordinates
    for formulation in ("crba", "aba"):
        cm = load(imp.model, tmp_path / formulation, formulation=formulation)
        _compare_floating_with_pinocchio(pin, imp, pin.buildModelFromUrdf(str(path)), cm)


def test_modelgen_load_takes_floating_base(tmp_path):
    cm = load(str(DATA / "double_pendulum.urdf"), tmp_path, floating_base=True)
    assert cm.coordinates[:2] == ("joint1", "joint2") and cm.nq == 9 and cm.n == 8
    assert cm.quaternions == ((5, 6, 7, 8),)
    with pytest.raises(TypeError, match="floating_base=True applies to a URDF"):
        as_spec(DATA.parent / "models" / "x.yaml", floating_base=True)


# -- files, entry points ----------------------------------------------------------

def test_import_names_coordinates_inputs_and_effects_in_depth_first_order():
    spec = import_urdf_text(EXOTIC, "exotic.urdf").model.spec()
    # j2-slide before j3 (its subtree), then j4; j5 is a mimic (no coordinate)
    assert spec.coordinates == ("j1", "j2_slide", "j3", "j4")
    assert spec.inputs == ("tau_j1", "tau_j2_slide", "tau_j3", "tau_j4")
    assert spec.parameters == (("g", 9.81),)
    assert spec.gravity == (0, 0, -symbol("g"))
    assert [e.name for e in spec.effects] == ["damping_j1"]
    # tool and frame_only are welded to b: one body for the three links
    assert sorted(b.name for b in spec.bodies) == ["a", "b", "c", "d", "e"]


def test_cli_import_writes_a_model_file_that_loads_to_the_same_spec(tmp_path):
    out = tmp_path / "ur5.yaml"
    assert main(["import", str(DATA / "ur5_robot.urdf"), "-o", str(out)]) == 0
    text = out.read_text()
    assert "#   shoulder_pan_joint: -6.28318530718 6.28318530718 3.15 150.0" in text
    assert load_model(out) == as_spec(DATA / "ur5_robot.urdf")


def test_modelgen_load_takes_a_urdf_path(tmp_path):
    cm = load(str(DATA / "double_pendulum.urdf"), tmp_path)
    assert cm.coordinates == ("joint1", "joint2")
    assert cm.inputs == ("tau_joint1", "tau_joint2")


def test_inertial_parameters_give_the_same_mass_matrix(tmp_path):
    numbers = load(import_urdf(DATA / "double_pendulum.urdf").model, tmp_path / "n")
    params = import_urdf(DATA / "double_pendulum.urdf", inertial_parameters=True).model
    spec = params.spec()
    assert "m_link1" in spec.parameter_names and "I_link1_xx" in spec.parameter_names
    cm = load(params, tmp_path / "p")
    q = np.array([0.3, -1.1])
    assert np.allclose(cm.mass_matrix(q), numbers.mass_matrix(q), rtol=1e-12, atol=0)


# -- errors -------------------------------------------------------------------------

def _robot(body: str) -> str:
    return f'<?xml version="1.0"?>\n<robot name="r">\n{body}\n</robot>\n'


LINKS = '<link name="a"/>\n<link name="b"/>'
#: the inertial of a link that a joint moves (a joint moving only massless links is refused)
BODY = ('<inertial><mass value="1"/><inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" '
        'izz="0.1"/></inertial>')


def _joint(name="j", kind="revolute", parent="a", child="b", extra=""):
    return (f'<joint name="{name}" type="{kind}"><parent link="{parent}"/>'
            f'<child link="{child}"/>{extra}</joint>')


@pytest.mark.parametrize("body, line, key, words", [
    (LINKS + "\n" + _joint() + "\n" + _joint("k", child="b"), 6, "joint[k].child",
     "has two parents"),
    (LINKS + "\n" + _joint(child="nowhere"), 5, "joint[j].child", "unknown link 'nowhere'"),
    (LINKS + '\n<joint type="revolute"/>', 5, "joint", "without a name"),
    ('<link/>', 3, "link", "without a name"),
    (LINKS + "\n" + _joint(kind="planar"), 5, "joint[j].type",
     "unsupported joint type 'planar'"),
    (LINKS + "\n" + _joint(extra='<origin xyz="0 0.1x 0"/>'), 5, "joint[j].origin.xyz",
     "malformed number '0.1x'"),
    (LINKS + "\n" + _joint(extra='<axis xyz="0 1"/>'), 5, "joint[j].axis", "needs 3 numbers"),
    (LINKS + "\n" + _joint(extra='<axis xyz="0 0 0"/>'), 5, "joint[j].axis", "axis is zero"),
    ('<link name="a"/>\n<link name="b"><inertial><mass value="1"/>\n'
     '<inertia ixx="1" iyy="1" izz="3" ixy="0" ixz="0" iyz="0"/></inertial></link>\n'
     + _joint(), 5, "link[b].inertial.inertia", "violates the triangle inequality"),
    ('<link name="a"/>\n<link name="b"><inertial><mass value="-1"/>'
     '<inertia ixx="1" iyy="1" izz="1" ixy="0" ixz="0" iyz="0"/></inertial></link>\n'
     + _joint(), 4, "link[b].inertial.mass", "negative mass"),
    (LINKS + "\n" + _joint(kind="floating", extra='<mimic joint="j"/>'), 5, "joint[j].mimic",
     "a floating joint cannot mimic"),
    (LINKS + "\n" + _joint(extra='<mimic joint="ghost"/>'), 5, "joint[j].mimic",
     "mimic of unknown joint 'ghost'"),
    (LINKS + '\n<link name="c"/>\n' + _joint(), 5, "robot", "2 root links"),
    (LINKS + "\n" + _joint(parent="b", child="a") + "\n" + _joint("k", parent="a", child="b"),
     2, "robot", "loop: every link has a parent joint"),
    (LINKS + '\n<link name="c"/>\n<link name="d"/>\n' + _joint() + "\n"
     + _joint("k", parent="c", child="d") + "\n" + _joint("l", parent="d", child="c"),
     8, "joint[k]", "cycle not connected to the root link 'a'"),
])
def test_bad_urdf_names_file_line_and_key(body, line, key, words):
    with pytest.raises(ModelError) as err:
        import_urdf_text(_robot(body), "bad.urdf")
    e = err.value
    assert (e.file, e.line, e.key) == ("bad.urdf", line, key), str(e)
    assert words in e.problem and e.fix


def test_floating_root_can_be_imported_fixed_with_a_note():
    text = _robot(LINKS + f'\n<link name="c">{BODY}</link>\n' + _joint("free", kind="floating")
                  + _joint("k", parent="b", child="c", extra='<axis xyz="0 0 1"/>'))
    imp = import_urdf_text(text, "f.urdf", fix_floating_root=True)
    assert imp.model.spec().coordinates == ("k",)
    assert "floating joint 'free' at the root was imported as fixed" in imp.model.description
    assert imp.notes and "floating joint 'free'" in urdf_to_yaml(imp)


def test_malformed_xml_and_entity_expansion_are_refused_with_a_line():
    with pytest.raises(ModelError, match=r"bad.urdf:3: malformed XML"):
        import_urdf_text('<robot name="r">\n<link name="a">\n</robot>', "bad.urdf")
    laughs = ('<?xml version="1.0"?>\n<!DOCTYPE r [\n<!ENTITY a "aaaaaaaaaa">\n'
              '<!ENTITY b "&a;&a;&a;&a;&a;&a;&a;&a;&a;&a;">\n]>\n<robot name="&b;"/>')
    with pytest.raises(ModelError, match=r"bad.urdf:3: entity declaration 'a' refused"):
        import_urdf_text(laughs, "bad.urdf")
    with pytest.raises(ModelError, match="cannot read the URDF file"):
        import_urdf(DATA / "missing.urdf")


def test_meshes_are_not_opened():
    text = _robot('<link name="a"><visual><geometry><mesh filename="/nonexistent/x.stl"/>'
                  f'</geometry></visual></link>\n<link name="b">{BODY}</link>\n'
                  + _joint(extra='<axis xyz="0 0 1"/>'))
    assert import_urdf_text(text).model.spec().coordinates == ("j",)


def test_shipped_ur5_model_is_the_import_of_its_urdf():
    shipped = Path(__file__).parent.parent / "models" / "robots" / "ur5.yaml"
    assert load_model(shipped) == as_spec(DATA / "ur5_robot.urdf")


# -- numbers at the limits of a double (issue 24) -----------------------------------

def _one_joint(axis: str, kind: str = "revolute", inertia: str = "") -> str:
    inertia = inertia or ('<inertial><origin xyz="0.1 0.2 0.3"/><mass value="1.5"/>'
                          '<inertia ixx="0.02" ixy="0.001" ixz="0" iyy="0.03" iyz="0" '
                          'izz="0.025"/></inertial>')
    return _robot(f'<link name="a"/>\n<link name="b">{inertia}</link>\n'
                  + _joint(kind=kind, extra=f'<axis xyz="{axis}"/>'))


@pytest.mark.parametrize("kind", ["revolute", "prismatic"])
@pytest.mark.parametrize("huge, unit", [("1e308 1e308 1e308", "1 1 1"),
                                        ("0 0 -1e308", "0 0 -1"),
                                        ("1e200 0 1e200", "1 0 1"),
                                        ("-1.7e308 1.7e308 0", "-1 1 0"),
                                        ("1e-300 1e-300 1e-300", "1 1 1"),
                                        ("5e-324 0 0", "1 0 0")])
def test_axes_whose_squares_overflow_or_underflow_keep_their_direction(kind, huge, unit):
    """The spec of a huge or tiny axis is the spec of the same direction written small:
    the normalisation scales by the largest component before squaring."""
    spec = import_urdf_text(_one_joint(huge, kind), "big.urdf").model.spec()
    assert spec == import_urdf_text(_one_joint(unit, kind), "big.urdf").model.spec()


def test_a_truly_zero_axis_is_still_refused():
    with pytest.raises(ModelError, match="axis is zero") as err:
        import_urdf_text(_one_joint("0 -0 0.0", "prismatic"), "zero.urdf")
    assert (err.value.file, err.value.line, err.value.key) == ("zero.urdf", 5, "joint[j].axis")


def _inertia(d, rotation=None, mass="1") -> str:
    """<inertial> of principal moments d (rotated by a fixed rotation), entries in %r."""
    r = rotation if rotation is not None else np.eye(3)
    m = r @ np.diag(d) @ r.T
    e = {k: repr(float(m[i, j])) for k, i, j in (("xx", 0, 0), ("xy", 0, 1), ("xz", 0, 2),
                                                  ("yy", 1, 1), ("yz", 1, 2), ("zz", 2, 2))}
    return (f'<inertial><mass value="{mass}"/><inertia ixx="{e["xx"]}" ixy="{e["xy"]}" '
            f'ixz="{e["xz"]}" iyy="{e["yy"]}" iyz="{e["yz"]}" izz="{e["zz"]}"/></inertial>')


@pytest.mark.parametrize("scale", [1.0, 1e300, 1e-300, 1.7e308 / 3])
def test_the_rigid_body_checks_are_the_same_at_any_scale(scale):
    """Principal moments (1, 1, 1.9) are physical, (0.5, 1, 1.9) are not, whatever the
    unit: the checks scale before squaring or summing (1e308 overflowed and passed)."""
    from modelgen.model.urdf_read import rpy_matrix
    r = rpy_matrix((0.3, -0.7, 1.1))
    good = _one_joint("0 0 1", inertia=_inertia(np.array([1.0, 1.0, 1.9]) * scale, r))
    import_urdf_text(good, "s.urdf").model.spec()
    bad = _one_joint("0 0 1", inertia=_inertia(np.array([0.5, 1.0, 1.9]) * scale, r))
    with pytest.raises(ModelError, match="violates the triangle inequality") as err:
        import_urdf_text(bad, "s.urdf")
    assert (err.value.line, err.value.key) == (4, "link[b].inertial.inertia")


def _welded(mass_a: str, inertia_a: str, mass_c: str, inertia_c: str, xyz: str) -> str:
    """Link b (moving) with link c welded to it at ``xyz``."""
    def inertial(mass, i):
        return (f'<inertial><mass value="{mass}"/><inertia ixx="{i}" ixy="0" ixz="0" '
                f'iyy="{i}" iyz="0" izz="{i}"/></inertial>')
    return _robot(f'<link name="a"/>\n<link name="b">{inertial(mass_a, inertia_a)}</link>\n'
                  f'<link name="c">{inertial(mass_c, inertia_c)}</link>\n'
                  + _joint(extra='<axis xyz="0 0 1"/>') + "\n"
                  + _joint("w", kind="fixed", parent="b", child="c",
                           extra=f'<origin xyz="{xyz}"/>'))


@pytest.mark.parametrize("text", [
    _welded("1", "1e308", "1", "1e308", "0 0 0"),           # inertias add to inf
    _welded("1e308", "1", "1e308", "1", "0 0 0"),           # masses add to inf
    _welded("1e300", "1", "1e300", "1", "1e10 0 0"),        # parallel-axis term m d^2
    _welded("1", "1", "1", "1", "1.7e308 0 0"),            # d^2 of a finite length
])
def test_merged_bodies_too_large_for_a_double_are_a_model_error(text):
    """Welding huge links gave inf and then OverflowError or ValueError ('internal error')."""
    with pytest.raises(ModelError, match="too large for a double") as err:
        import_urdf_text(text, "huge.urdf")
    e = err.value
    assert (e.file, e.line, e.key) == ("huge.urdf", 4, "link[b].inertial") and e.fix


def test_huge_but_finite_merged_bodies_are_exact():
    """Two welded links of mass 1e-300, 2e200 m apart: the squared distance overflows
    if formed first, the merged inertia (2e100) does not."""
    spec = import_urdf_text(_welded("1e-300", "0", "1e-300", "0", "2e200 0 0"), "b.urdf") \
        .model.spec()
    body = next(b for b in spec.bodies if b.name == "b")
    # two equal masses m = 1e-300 at 0 and 2e200: about the middle, 2 m (1e200)^2 on y, z
    assert float(body.mass) == 2e-300
    assert [float(body.inertia[k][k]) for k in range(3)] == pytest.approx([0, 2e100, 2e100],
                                                                            rel=1e-15)


@pytest.mark.parametrize("place, key", [
    ('<origin xyz="0 nan 0"/>', "joint[j].origin.xyz"),
    ('<origin rpy="inf 0 0"/>', "joint[j].origin.rpy"),
    ('<axis xyz="0 0 1e999"/>', "joint[j].axis"),
    ('<axis xyz="0 0 1"/><limit lower="-inf" upper="1" effort="1" velocity="1"/>',
     "joint[j].limit.lower"),
    ('<axis xyz="0 0 1"/><dynamics damping="NaN"/>', "joint[j].dynamics.damping"),
])
def test_non_finite_numbers_in_joints_are_a_model_error_with_a_line(place, key):
    with pytest.raises(ModelError, match="malformed number") as err:
        import_urdf_text(_robot(LINKS + "\n" + _joint(extra=place)), "nan.urdf")
    assert (err.value.file, err.value.line, err.value.key) == ("nan.urdf", 5, key)


@pytest.mark.parametrize("mass, ixx", [("nan", "1"), ("1", "inf"), ("1e999", "1"),
                                       ("1", "-1e999")])
def test_non_finite_masses_and_inertias_are_a_model_error_with_a_line(mass, ixx):
    text = _robot(f'<link name="a"/>\n<link name="b"><inertial><mass value="{mass}"/>\n'
                  f'<inertia ixx="{ixx}" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/>'
                  '</inertial></link>\n' + _joint())
    with pytest.raises(ModelError, match="malformed number") as err:
        import_urdf_text(text, "nan.urdf")
    assert err.value.file == "nan.urdf" and err.value.line in (4, 5)


# -- inertias of the physical body, and the ways through for vendor files (issue 23) --

def test_rounding_noise_in_an_inertia_passes_and_particles_stay_particles():
    """icub's head: ixx = iyy = izz = 0, ixz = 2.4e-35 (principal moments -2.4e-35, 0,
    2.4e-35) on a 1.34 kg link, noise against its m |c|^2; a particle stays zero."""
    head = ('<inertial><origin xyz="0.0185 -0.1108 6.78454e-18"/><mass value="1.33687"/>'
            '<inertia ixx="0" ixy="0" ixz="2.40741e-35" iyy="0" iyz="0" izz="0"/></inertial>')
    spec = import_urdf_text(_one_joint("0 0 1", inertia=head), "icub.urdf").model.spec()
    assert spec.bodies[0].inertia[0][2] == sympy.Rational("2.40741e-35")
    particle = ('<inertial><origin xyz="0.1 0 0"/><mass value="2"/>'
                '<inertia ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"/></inertial>')
    spec = import_urdf_text(_one_joint("0 0 1", inertia=particle), "p.urdf").model.spec()
    assert all(x == 0 for row in spec.bodies[0].inertia for x in row)
    # the same noise relative to the body's own scale is not noise: moments (-1, 0, 1)
    bad = head.replace("2.40741e-35", "1e-3")
    with pytest.raises(ModelError, match="negative principal moment"):
        import_urdf_text(_one_joint("0 0 1", inertia=bad), "icub.urdf")


#: anymal's ``base``: a dummy link (mass 1e-6, all six entries 1e-6: principal moments
#: 0, 0, 3e-6, no rigid body) welded to ``base_inertia``, which carries the real body
DUMMY = ('<inertial><mass value="1e-6"/><inertia ixx="1e-6" ixy="1e-6" ixz="1e-6" '
         'iyy="1e-6" iyz="1e-6" izz="1e-6"/></inertial>')
REAL = ('<inertial><origin xyz="-0.002 0.0004 0.04"/><mass value="16.8"/>'
        '<inertia ixx="0.27" ixy="0.0004" ixz="0.0013" iyy="0.5" iyz="-0.00003" '
        'izz="0.53"/></inertial>')


def _dummy_robot(welded: bool) -> str:
    inner = (f'<link name="base_inertia">{REAL}</link>\n'
             + _joint("w", kind="fixed", parent="base", child="base_inertia",
                      extra='<origin xyz="0.01 0 0.02"/>') if welded else "")
    return _robot(f'<link name="world"/>\n<link name="base">{DUMMY}</link>\n{inner}\n'
                  + _joint(kind="continuous", parent="world", child="base",
                           extra='<axis xyz="0 1 0"/>'))


def test_a_dummy_link_is_checked_merged_with_the_links_welded_to_it(pin, tmp_path):
    path = tmp_path / "dummy.urdf"
    path.write_text(_dummy_robot(welded=True))
    imp = import_urdf(path)
    assert [b.name for b in imp.model.spec().bodies] == ["base"] and not imp.notes
    _compare_with_pinocchio(pin, path, tmp_path / "build", samples=2)
    with pytest.raises(ModelError, match="violates the triangle inequality") as err:
        import_urdf_text(_dummy_robot(welded=False), "dummy.urdf")
    assert err.value.key == "link[base].inertial.inertia"


#: allegro's link_11.0: principal moments 2.30e-6 + 3.49e-6 < 7.27e-6
ALLEGRO = _inertia([2.30064e-6, 3.49154e-6, 7.27306e-6],
                   np.array([[0.36, 0.48, -0.8], [-0.8, 0.6, 0.0], [0.48, 0.64, 0.6]]),
                   mass="0.0388")


def test_a_non_physical_inertia_is_refused_and_the_fix_names_the_options():
    with pytest.raises(ModelError, match="violates the triangle inequality") as err:
        import_urdf_text(_one_joint("0 0 1", inertia=ALLEGRO), "allegro.urdf")
    assert 'inertia="as_is"' in err.value.fix and "--inertia as-is" in err.value.fix
    assert 'inertia="balance"' in err.value.fix and "--inertia balance" in err.value.fix


def test_inertia_as_is_keeps_the_files_values_with_a_warning(tmp_path):
    text = _one_joint("0 0 1", inertia=ALLEGRO)
    with pytest.warns(UserWarning, match=r"link 'b' is not that of a rigid body.*past the "
                                         r"triangle inequality"):
        imp = import_urdf_text(text, "allegro.urdf", inertia="as_is")
    spec = imp.model.spec()
    assert not spec.physical_inertia
    entries = {k: float(v) for k, v in zip(("ixx", "iyy", "izz"),
                                          (spec.bodies[0].inertia[k][k] for k in range(3)))}
    for k, v in entries.items():
        assert f'{k}="{v!r}"' in text          # exactly the file's numbers
    # the model file says so, and loads to the same spec
    yaml = urdf_to_yaml(imp)
    assert "physical_inertia: false" in yaml and '# Read with inertia="as_is"' in yaml
    out = tmp_path / "allegro.yaml"
    out.write_text(yaml)
    assert load_model(out) == spec


def test_inertia_balance_applies_mujocos_rule(tmp_path):
    """MuJoCo's balanceinertia: all three principal moments set to their mean."""
    with pytest.warns(UserWarning, match=r"link 'b' balanced"):
        imp = import_urdf_text(_one_joint("0 0 1", inertia=ALLEGRO), "allegro.urdf",
                               inertia="balance")
    spec = imp.model.spec()
    mean = (2.30064e-6 + 3.49154e-6 + 7.27306e-6) / 3
    inertia = np.array([[float(x) for x in row] for row in spec.bodies[0].inertia])
    assert np.allclose(inertia, mean * np.eye(3), rtol=1e-12, atol=0)
    assert spec.physical_inertia and any("balanced" in n for n in imp.notes)
    out = tmp_path / "allegro.yaml"
    out.write_text(urdf_to_yaml(imp))
    assert load_model(out) == spec and "physical_inertia" not in out.read_text()


def test_massless_moving_links_are_refused_or_bounded_as_mujoco_does():
    """romeo's LHand moves only massless links: A is singular for every q."""
    text = _robot(LINKS + "\n" + _joint(extra='<axis xyz="0 0 1"/>'))
    with pytest.raises(ModelError, match="moves only massless links") as err:
        import_urdf_text(text, "hand.urdf")
    assert "min_mass=" in err.value.fix and "--min-inertia" in err.value.fix
    with pytest.warns(UserWarning, match="min_mass"):
        spec = import_urdf_text(text, "hand.urdf", min_mass=1e-3,
                                min_inertia=1e-6).model.spec()
    body = spec.bodies[0]
    assert float(body.mass) == 1e-3
    assert np.allclose([[float(x) for x in row] for row in body.inertia], 1e-6 * np.eye(3),
                       rtol=1e-15, atol=0)
    # bounds leave heavier bodies alone
    heavy = import_urdf_text(_one_joint("0 0 1"), "h.urdf").model.spec()
    assert import_urdf_text(_one_joint("0 0 1"), "h.urdf", min_mass=1e-3,
                            min_inertia=1e-6).model.spec().bodies == heavy.bodies
    with pytest.raises(ValueError, match="min_mass"):
        import_urdf_text(text, "hand.urdf", min_mass=float("nan"))
    with pytest.raises(ValueError, match="inertia='heavy'"):
        import_urdf_text(text, "hand.urdf", inertia="heavy")


def test_a_fixed_robot_without_joints_is_refused_and_flies_with_a_floating_base(tmp_path):
    text = _robot('<link name="frame">' + REAL + "</link>")
    with pytest.raises(ModelError, match="no moving joint") as err:
        import_urdf_text(text, "quad.urdf")
    assert "floating_base=True" in err.value.fix and "--floating-base" in err.value.fix
    spec = import_urdf_text(text, "quad.urdf", floating_base=True).model.spec()
    assert spec.n == 6 and spec.nq == 7


def test_reading_options_reach_as_spec_load_and_the_command_line(tmp_path, capsys):
    path = tmp_path / "allegro.urdf"
    path.write_text(_one_joint("0 0 1", inertia=ALLEGRO))
    with pytest.warns(UserWarning):
        spec = as_spec(path, inertia="balance", min_mass=1e-3)
    with pytest.raises(TypeError, match="apply to a URDF"):
        as_spec(DATA.parent / "models" / "x.yaml", inertia="balance")
    with pytest.warns(UserWarning):
        assert load(path, tmp_path / "b", inertia="balance").mass_matrix([0.3]).shape == (1, 1)
    out = tmp_path / "allegro.yaml"
    assert main(["import", str(path), "-o", str(out)]) != 0      # refused by default
    assert "--inertia as-is" in capsys.readouterr().err
    with pytest.warns(UserWarning):
        assert main(["import", str(path), "-o", str(out), "--inertia", "balance",
                     "--min-mass", "1e-3"]) == 0
    assert load_model(out) == spec
    assert '# Read with inertia="balance", min_mass=0.001' in out.read_text()
    with pytest.raises(SystemExit):
        main(["import", str(path), "--min-inertia", "-1"])


def test_physical_inertia_false_in_a_model_file_takes_inertias_as_given():
    from modelgen.model import parse_model
    body = ("coordinates: [q]\nbases: {B: {parent: E, axis: 3, angle: q}}\n"
            "bodies: {b: {mass: 1, G: O, base: B, inertia: [1, 1, 3]}}\n")
    with pytest.raises(ModelError, match="triangle inequality"):
        parse_model("name: m\n" + body, "m.yaml")
    spec = parse_model("name: m\nphysical_inertia: false\n" + body, "m.yaml")
    assert not spec.physical_inertia and spec.bodies[0].inertia[2][2] == 3
    from modelgen.model import Model, spec_to_yaml
    assert parse_model(spec_to_yaml(spec)) == spec == Model.from_spec(spec).spec()
    with pytest.raises(ModelError, match="expected true or false") as err:
        parse_model("name: m\nphysical_inertia: 3\n", "m.yaml")
    assert (err.value.line, err.value.key) == (2, "physical_inertia")


# -- found by the URDF fuzz (bench/fuzz.py --urdf), issue 24 ---------------------------

@pytest.mark.parametrize("kind", ["fixed", "floating"])
@pytest.mark.parametrize("axis", ["nan 0 1", "inf 0 0", "0 0 1e999", "1 x 0"])
def test_a_non_finite_axis_of_a_joint_without_one_is_refused_not_skipped(kind, axis):
    """A fixed joint's axis is unused, but a NaN in it was accepted silently."""
    text = _robot(LINKS + f'\n<link name="c">{BODY}</link>\n'
                  + _joint(kind=kind, extra=f'<axis xyz="{axis}"/>') + "\n"
                  + _joint("k", parent="b", child="c", extra='<axis xyz="0 0 1"/>'))
    with pytest.raises(ModelError, match="malformed number") as err:
        import_urdf_text(text, "axis.urdf")
    assert (err.value.file, err.value.line, err.value.key) == ("axis.urdf", 6, "joint[j].axis")


@pytest.mark.parametrize("name, model", [("True", "True_robot"), ("lambda", "lambda_robot"),
                                         ("int", "int_robot"), ("None", "None_robot"),
                                         ("9lives", "robot_9lives")])
def test_a_robot_named_by_a_keyword_gets_a_valid_model_name(name, model):
    """<robot name="True"> raised a ModelError naming '<api>' and no line."""
    text = _one_joint("0 0 1").replace('<robot name="r">', f'<robot name="{name}">')
    assert import_urdf_text(text, "kw.urdf").model.spec().name == model


def test_an_empty_robot_is_refused_with_its_line_and_a_fix_naming_xacro():
    """example-robot-data's ur3.urdf: a <robot> without name, links or joints."""
    text = ('<?xml version="1.0"?>\n<!-- made by xacro -->\n'
            '<robot xmlns:xacro="http://wiki.ros.org/xacro">\n  <!-- only macros -->\n</robot>\n')
    with pytest.raises(ModelError, match="the <robot> element is empty") as err:
        import_urdf_text(text, "ur3.urdf")
    e = err.value
    assert (e.file, e.line, e.key) == ("ur3.urdf", 3, "robot") and "xacro" in e.fix


# -- mimic="ignore" (issue 23: alex_psyonic_hands) -----------------------------------------

MIMIC_OF_A_GHOST = _robot(LINKS + f'\n<link name="c">{BODY}</link>\n<link name="d">{BODY}</link>\n'
                          + _joint(child="c", extra='<axis xyz="0 0 1"/>') + "\n"
                          + _joint("k", parent="c", child="d",
                                   extra='<axis xyz="0 1 0"/><mimic joint="ghost_q1" '
                                         'multiplier="2" offset="0.5"/>')
                          + '\n' + _joint("w", kind="fixed", child="b"))


def test_a_mimic_of_a_missing_joint_is_refused_and_the_fix_names_mimic_ignore():
    with pytest.raises(ModelError, match="mimic of unknown joint 'ghost_q1'") as err:
        import_urdf_text(MIMIC_OF_A_GHOST, "hand.urdf")
    assert (err.value.line, err.value.key) == (8, "joint[k].mimic")
    assert 'mimic="ignore"' in err.value.fix and "--mimic ignore" in err.value.fix


def test_mimic_ignore_gives_every_joint_a_coordinate_as_pinocchio_mimic_false():
    with pytest.warns(UserWarning, match=r"mimic=\"ignore\".*joint 'k' \(of 'ghost_q1'\)"):
        imp = import_urdf_text(MIMIC_OF_A_GHOST, "hand.urdf", mimic="ignore")
    spec = imp.model.spec()
    assert spec.coordinates == ("j", "k") and spec.inputs == ("tau_j", "tau_k")
    # the same robot written without the mimic tag
    plain = import_urdf_text(MIMIC_OF_A_GHOST.replace(
        '<mimic joint="ghost_q1" multiplier="2" offset="0.5"/>', ""), "hand.urdf")
    assert spec.bases == plain.model.spec().bases and spec.bodies == plain.model.spec().bodies
    assert 'Read with mimic="ignore"' in urdf_to_yaml(imp)
    # a file whose mimics are all valid: ignore makes the mimic joint a joint of its own
    with pytest.warns(UserWarning, match="mimic"):
        assert import_urdf_text(EXOTIC, "x.urdf", mimic="ignore").model.spec().n == 5
    assert import_urdf_text(EXOTIC, "x.urdf").model.spec().n == 4
    with pytest.raises(ValueError, match="mimic='loose'"):
        import_urdf_text(EXOTIC, "x.urdf", mimic="loose")


def test_mimic_ignore_reaches_as_spec_load_and_the_command_line(tmp_path, capsys):
    path = tmp_path / "hand.urdf"
    path.write_text(MIMIC_OF_A_GHOST)
    with pytest.warns(UserWarning):
        spec = as_spec(path, mimic="ignore")
    assert spec.n == 2
    with pytest.raises(TypeError, match="apply to a URDF"):
        as_spec(DATA.parent / "models" / "x.yaml", mimic="ignore")
    with pytest.warns(UserWarning):
        assert load(path, tmp_path / "b", mimic="ignore").mass_matrix([0.3, 0.1]).shape \
            == (2, 2)
    out = tmp_path / "hand.yaml"
    assert main(["import", str(path), "-o", str(out)]) != 0
    assert "--mimic ignore" in capsys.readouterr().err
    with pytest.warns(UserWarning):
        assert main(["import", str(path), "-o", str(out), "--mimic", "ignore"]) == 0
    assert load_model(out) == spec and '# Read with mimic="ignore"' in out.read_text()
    from modelgen.codegen.options import BuildOptions
    assert BuildOptions(mimic="ignore").reading()["mimic"] == "ignore"
    assert "mimic='ignore'" in BuildOptions(mimic="ignore").key_text()


# -- armature from Drake's rotor extension ---------------------------------------------

def _with_rotor(actuator: str, joint: str = "j") -> str:
    return _one_joint("0 0 1").replace("</robot>", (
        f'<transmission name="t"><type>transmission_interface/SimpleTransmission</type>'
        f'<joint name="{joint}"><hardwareInterface>EffortJointInterface</hardwareInterface>'
        f'</joint>\n<actuator name="m"><mechanicalReduction>50</mechanicalReduction>'
        f'{actuator}</actuator></transmission>\n</robot>'))


def test_drakes_rotor_inertia_and_gear_ratio_are_the_joints_armature(tmp_path):
    """Drake reflects a rotor as rotor_inertia * gear_ratio^2 on the joint's diagonal
    of A; the compiled model's A differs from the one without the rotor by exactly that."""
    text = _with_rotor('<drake:rotor_inertia value="0.001"/><drake:gear_ratio value="50"/>')
    imp = import_urdf_text(text, "rotor.urdf")
    spec = imp.model.spec()
    assert spec.armature == (("j", sympy.Rational(5, 2)),)
    from modelgen.model import parse_model
    assert parse_model(urdf_to_yaml(imp)) == spec       # modelgen import keeps it
    bare = import_urdf_text(_one_joint("0 0 1"), "rotor.urdf").model.spec()
    q = [0.4]
    a_rotor = load(spec, tmp_path / "r").mass_matrix(q)
    a_bare = load(bare, tmp_path / "b").mass_matrix(q)
    assert a_rotor[0, 0] - a_bare[0, 0] == pytest.approx(0.001 * 50 ** 2, rel=1e-13)
    # the gear ratio defaults to 1, as Drake's; a transmission without the extension,
    # or with mechanicalReduction only, adds nothing (nothing says what the rotor weighs)
    only = import_urdf_text(_with_rotor('<drake:rotor_inertia value="0.25"/>'), "r.urdf")
    assert only.model.spec().armature == (("j", sympy.Rational(1, 4)),)
    assert import_urdf_text(_with_rotor(""), "r.urdf").model.spec().armature == ()


@pytest.mark.parametrize("actuator, joint, words", [
    ('<drake:rotor_inertia value="nan"/>', "j", "malformed number"),
    ('<drake:rotor_inertia value="-1"/>', "j", "negative rotor inertia"),
    ('<drake:rotor_inertia/>', "j", "missing attribute 'value'"),
    ('<drake:rotor_inertia value="1"/><drake:gear_ratio value="1e200"/>', "j",
     "too large for a double"),
    ('<drake:rotor_inertia value="1"/>', "ghost", "transmission of unknown joint 'ghost'"),
])
def test_bad_rotor_extensions_are_model_errors_with_a_line(actuator, joint, words):
    with pytest.raises(ModelError, match=words) as err:
        import_urdf_text(_with_rotor(actuator, joint), "rotor.urdf")
    assert err.value.file == "rotor.urdf" and err.value.line and err.value.fix


def test_a_rotor_on_a_joint_without_a_coordinate_is_refused():
    text = _robot(LINKS + f'\n<link name="c">{BODY}</link>\n' + _joint(kind="fixed") + "\n"
                  + _joint("k", parent="b", child="c", extra='<axis xyz="0 0 1"/>')
                  + '<transmission name="t"><joint name="j"/><actuator name="m">'
                    '<drake:rotor_inertia value="1"/></actuator></transmission>')
    with pytest.raises(ModelError, match="a rotor on joint 'j', which has no coordinate"):
        import_urdf_text(text, "rotor.urdf")


def test_an_inertia_the_model_refuses_names_the_urdf_file_and_line():
    """Moments (-1, 1, 3) pass the import's noise test against m |c|^2 = 1e300, but
    the model's own check refused them as '<api>', without file or line (fuzz)."""
    heavy = ('<inertial><origin xyz="1 0 0"/><mass value="1e300"/>\n'
             '<inertia ixx="1" ixy="2" ixz="0" iyy="1" iyz="0" izz="1"/></inertial>')
    with pytest.raises(ModelError, match="negative principal moment") as err:
        import_urdf_text(_one_joint("0 0 1", inertia=heavy), "heavy.urdf")
    e = err.value
    assert (e.file, e.line, e.key) == ("heavy.urdf", 5, "link[b].inertial.inertia")
    assert 'inertia="as_is"' in e.fix
    spec = import_urdf_text(_one_joint("0 0 1", inertia=heavy), "heavy.urdf",
                            inertia="as_is").model.spec()         # the way through
    assert spec.bodies[0].inertia[0][1] == 2 and not spec.physical_inertia


@pytest.mark.parametrize("name", ["1e308", "int", "lambda"])
def test_a_floating_joint_with_an_invalid_name_is_refused_at_its_line(name):
    """As a revolute joint's: a floating joint '1e308' was refused as '<api>' (fuzz)."""
    text = _robot(LINKS + f'\n<link name="c">{BODY}</link>\n'
                  + _joint(kind="revolute", child="b", extra='<axis xyz="0 0 1"/>') + "\n"
                  + _joint(name, kind="floating", parent="b", child="c"))
    with pytest.raises(ModelError) as err:
        import_urdf_text(text, "free.urdf")
    assert (err.value.file, err.value.line, err.value.key) == ("free.urdf", 7,
                                                               f"joint[{name}]")
