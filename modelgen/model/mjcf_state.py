"""MuJoCo's qpos, qvel and qacc <-> modelgen's q, v and qdd of an MJCF import
(``imported``, a :class:`modelgen.model.mjcf.MjcfImport`, whose ``qpos_index``,
``dof_index`` and ``free`` say where each value goes).

Only the order differs, except for a free joint's linear velocity, which is in
the world frame in MuJoCo's ``qvel`` and in the body frame in modelgen's speeds
(Pinocchio's free-flyer): :func:`velocity_map` turns it.
"""
from __future__ import annotations

import numpy as np

__all__ = ["quat_matrix", "qpos_from_mujoco", "qpos_to_mujoco", "qvel_from_mujoco",
           "qvel_to_mujoco", "qacc_to_mujoco", "velocity_map"]


def quat_matrix(q) -> np.ndarray:
    """Rotation matrix of a unit quaternion (w, x, y, z)."""
    w, x, y, z = np.asarray(q, dtype=float) / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def qpos_from_mujoco(imported, qpos) -> np.ndarray:
    """modelgen's q from MuJoCo's ``qpos`` (a reordering: the values are the same)."""
    return np.asarray(qpos, dtype=float)[list(imported.qpos_index)]


def qpos_to_mujoco(imported, q) -> np.ndarray:
    """MuJoCo's ``qpos`` from modelgen's q."""
    out = np.empty(len(imported.qpos_index))
    out[list(imported.qpos_index)] = np.asarray(q, dtype=float)
    return out


def _free_rotations(imported, q) -> list:
    """(dof index of vx, R) of each free joint, R its body's rotation in E."""
    q = np.asarray(q, dtype=float)
    return [(dof, quat_matrix(q[k:k + 4])) for k, dof in imported.free]


def velocity_map(imported, q) -> np.ndarray:
    """T with MuJoCo's ``qvel = T v`` at modelgen's configuration q: a permutation,
    with each free joint's linear velocity turned from its body frame to the world.
    ``T^T M T`` is modelgen's A (M: MuJoCo's ``mj_fullM``)."""
    n = len(imported.dof_index)
    T = np.zeros((n, n))
    T[list(imported.dof_index), range(n)] = 1.0
    for dof, R in _free_rotations(imported, q):
        rows = [imported.dof_index[dof + i] for i in range(3)]
        T[np.ix_(rows, range(dof, dof + 3))] = R
    return T


def qvel_to_mujoco(imported, q, v) -> np.ndarray:
    """MuJoCo's ``qvel`` from modelgen's q and v."""
    return velocity_map(imported, q) @ np.asarray(v, dtype=float)


def qvel_from_mujoco(imported, qpos, qvel) -> np.ndarray:
    """modelgen's v from MuJoCo's ``qpos`` and ``qvel``."""
    q = qpos_from_mujoco(imported, qpos)
    return velocity_map(imported, q).T @ np.asarray(qvel, dtype=float)


def qacc_to_mujoco(imported, q, v, qdd) -> np.ndarray:
    """MuJoCo's ``qacc`` from modelgen's q, v and qdd: ``T qdd + dT/dt v``; a free
    joint's world-frame linear acceleration is ``R (dv/dt + w x v)``."""
    v = np.asarray(v, dtype=float)
    out = velocity_map(imported, q) @ np.asarray(qdd, dtype=float)
    for dof, R in _free_rotations(imported, q):
        rows = [imported.dof_index[dof + i] for i in range(3)]
        out[rows] += R @ np.cross(v[dof + 3:dof + 6], v[dof:dof + 3])
    return out
