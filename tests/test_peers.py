"""The peers' models of ``modelgen.bench.peers`` for a floating-base robot: the MJCF
written from Pinocchio's solo12 with a free flyer is the same model, MuJoCo's
state and accelerations mapped from Pinocchio's (bench/derivatives.py's solo12 row)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from modelgen.bench import peers

SOLO12 = Path(__file__).resolve().parent / "data" / "urdf" / "solo12.urdf"


def test_mjcf_of_floating_solo12_gives_pinocchios_accelerations(tmp_path):
    pin = pytest.importorskip("pinocchio")
    mujoco = pytest.importorskip("mujoco")
    model = pin.buildModelFromUrdf(str(SOLO12), pin.JointModelFreeFlyer())
    links = peers.pinocchio_links(model)
    assert [link[1] for link in links].count("free") == 1
    rng = np.random.default_rng(7)
    data = model.createData()
    for k in range(3):
        q = pin.randomConfiguration(model, -np.ones(model.nq), np.ones(model.nq))
        v, tau = rng.uniform(-2, 2, model.nv), rng.uniform(-1, 1, model.nv)
        tau[:6] = 0.0       # joint efforts only (MuJoCo's free-joint force is in world axes)
        xml, tree, state = peers.write_pinocchio_peer_models("solo12", model, q, v,
                                                             tmp_path / str(k))
        assert tree.read_text().split()[0] == str(model.njoints - 1)
        mj = mujoco.MjModel.from_xml_path(str(xml))
        mj_data = mujoco.MjData(mj)
        assert (mj.nq, mj.nv) == (model.nq, model.nv)
        mj_data.qpos[:], mj_data.qvel[:] = state[:mj.nq], state[mj.nq:]
        mj_data.qfrc_applied[:] = tau
        mujoco.mj_forward(mj, mj_data)
        want = peers.mujoco_acceleration(links, q, v, pin.aba(model, data, q, v, tau))
        assert np.max(np.abs(mj_data.qacc - want)) <= 1e-9 * np.max(np.abs(want))
        # every body frame's velocity at its origin in world axes: MuJoCo's reading of the
        # mapped qvel (the accelerations alone do not see the base's linear velocity)
        pin.forwardKinematics(model, data, q, v)
        for jid in range(1, model.njoints):
            got = np.zeros(6)
            mujoco.mj_objectVelocity(mj, mj_data, mujoco.mjtObj.mjOBJ_XBODY, jid, got, 0)
            twist = pin.getVelocity(model, data, jid, pin.LOCAL_WORLD_ALIGNED)
            expected = np.concatenate([twist.angular, twist.linear])
            assert np.max(np.abs(got - expected)) <= 1e-9 * np.max(np.abs(v))
