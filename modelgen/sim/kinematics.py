"""Frame kinematics from Python: poses, velocities, Jacobians, bias accelerations,
the centre of mass and the centroidal momentum matrix, as numpy arrays.

The compiled functions (``<name>_frame_*``, ``<name>_com*``,
``<name>_centroidal_momentum_matrix``) exist when the model was built with
``kinematics=`` (``modelgen.load(path, kinematics={"frames": ["tool0"], "com":
True})``, or ``frames=["tool0"]``).  They compute in one reference (the build's,
``local_world_aligned`` by default); the methods here convert to the other two
with the frame's pose, so every Pinocchio convention is available:

* ``local_world_aligned``: E's axes, at the frame's origin;
* ``world``: E's axes, the body-fixed point at O;
* ``local``: the frame's own axes, at its origin.

Rows of 6-vectors and 6 x nv Jacobians: linear first, then angular, as
Pinocchio's.  :class:`FrameKinematics` is a base class of
:class:`~modelgen.sim.runtime.CompiledModel`.

The quaternions of ball and free joints in ``q`` are taken as ``simulate``
takes them in ``x0``: a zero one is refused, the others normalised (the
rotation of ``s * u`` is that of the unit quaternion ``u``).
"""
from __future__ import annotations

import numpy as np

from modelgen.codegen.options import REFERENCES
from modelgen.errors import SimulationError
from modelgen.sim.integrate import check_quaternions


#: the routines that take the speeds v after q
SPEED_ROUTINES = ("frame_velocities", "frame_bias_accelerations")


def _to_aligned(reference: str, R, r, linear, angular):
    """(linear, angular) in ``reference`` -> in local_world_aligned (columns work too)."""
    if reference == "local":
        return R @ linear, R @ angular
    if reference == "world":
        return linear + np.cross(angular, r, axis=0), angular
    return linear, angular


def _from_aligned(reference: str, R, r, linear, angular):
    """(linear, angular) in local_world_aligned -> in ``reference``."""
    if reference == "local":
        return R.T @ linear, R.T @ angular
    if reference == "world":
        return linear - np.cross(angular, r, axis=0), angular
    return linear, angular


class FrameKinematics:
    """The kinematics methods of a compiled model (see the module)."""

    def _kinematics(self) -> dict:
        info = self.manifest.get("kinematics")
        if not info:
            raise SimulationError(
                f"{self.name}: no kinematics were generated; load the model with "
                "kinematics={'frames': [...], 'com': True, 'centroidal': True} (or "
                "frames=[...])")
        return info

    def _kin_call(self, routine: str, shape: tuple, q, p, v=None) -> np.ndarray:
        self._kinematics()
        fn = getattr(self.lib, f"{self.name}_{routine}", None)
        if fn is None:
            raise SimulationError(
                f"{self.name}: {routine} was not generated; build with "
                + {"frame_bias_accelerations": "kinematics={..., 'bias_acceleration': True}",
                   "com": "kinematics={..., 'com': True}",
                   "com_jacobian": "kinematics={..., 'com': True}",
                   "centroidal_momentum_matrix": "kinematics={..., 'centroidal': True}"
                   }.get(routine, "kinematics={'frames': [...]}"))
        q = self._vector(q, self.nq, "q")
        if self.quaternions:
            # the C reads a quaternion as a rotation only when it is a unit one: as
            # simulate does, refuse a zero one and normalise the others
            check_quaternions(self, q[None, :], "q")
            q = self.project(q)
        out = np.empty(shape)
        args = [self._ptr(q)]
        if routine in SPEED_ROUTINES:       # v=None is no speeds, not zero speeds
            args.append(self._ptr(self._vector(v, self.n, "v")))
        fn(*args, self._ptr(self.params(p)), self._ptr(out))
        return out

    @property
    def frames(self) -> tuple:
        """The frames the build computes (in the order of the C arrays)."""
        return tuple((self.manifest.get("kinematics") or {}).get("frames", ()))

    def _frame_index(self, frame: str) -> int:
        frames = self._kinematics()["frames"]
        if frame not in frames:
            raise SimulationError(
                f"{self.name}: no frame {frame!r} in this build; it has "
                + (", ".join(frames) if frames else "none")
                + " (list the frame in kinematics={'frames': [...]})")
        return frames.index(frame)

    def _reference(self, reference) -> tuple:
        built = self._kinematics()["reference"]
        reference = built if reference is None else reference
        if reference not in REFERENCES:
            raise SimulationError(f"{self.name}: reference must be one of "
                                  f"{', '.join(REFERENCES)}, got {reference!r}")
        return built, reference

    def frame_pose(self, q, frame: str, p=None) -> np.ndarray:
        """The 4x4 pose ``[[R, r], [0, 0, 0, 1]]`` of ``frame``: R's columns are its
        unit vectors in E, r its origin from O (Pinocchio's ``oMf``).

        >>> cm = modelgen.load("ur5.urdf", frames=["tool0"])        # doctest: +SKIP
        >>> cm.frame_pose(q, "tool0")[:3, 3]                         # doctest: +SKIP
        """
        i = self._frame_index(frame)
        return self._kin_call("frame_poses", (len(self.frames), 4, 4), q, p)[i]

    def frame_jacobian(self, q, frame: str, reference=None, p=None) -> np.ndarray:
        """The 6 x nv Jacobian of ``frame`` (rows linear then angular; columns the
        speeds, free and ball joints in the tangent space) in ``reference`` (default:
        the build's), as Pinocchio's ``getFrameJacobian``.

        >>> J = cm.frame_jacobian(q, "tool0", reference="local")    # doctest: +SKIP
        """
        i = self._frame_index(frame)
        built, reference = self._reference(reference)
        J = self._kin_call("frame_jacobians", (len(self.frames), 6, self.n), q, p)[i]
        if built == reference:
            return J
        T = self.frame_pose(q, frame, p)
        R, r = T[:3, :3], T[:3, 3:4]
        lin, ang = _to_aligned(built, R, r, J[:3], J[3:])
        return np.vstack(_from_aligned(reference, R, r, lin, ang))

    def frame_velocity(self, q, v, frame: str, reference=None, p=None) -> np.ndarray:
        """The spatial velocity ``J v`` of ``frame`` (6: linear then angular) in
        ``reference``, as Pinocchio's ``getFrameVelocity``."""
        i = self._frame_index(frame)
        built, reference = self._reference(reference)
        V = self._kin_call("frame_velocities", (len(self.frames), 6), q, p, v)[i]
        if built == reference:
            return V
        T = self.frame_pose(q, frame, p)
        R, r = T[:3, :3], T[:3, 3]
        lin, ang = _to_aligned(built, R, r, V[:3], V[3:])
        return np.concatenate(_from_aligned(reference, R, r, lin, ang))

    def frame_bias_acceleration(self, q, v, frame: str, reference=None, p=None) -> np.ndarray:
        """The classical acceleration of ``frame``'s origin with zero speed derivatives
        (6: linear then angular), as Pinocchio's ``getFrameClassicalAcceleration``
        after ``forwardKinematics(q, v, 0)``.  In ``local_world_aligned`` it is
        exactly ``J_dot v``: the task acceleration is ``J a + frame_bias_acceleration``.
        """
        i = self._frame_index(frame)
        built, reference = self._reference(reference)
        acc = self._kin_call("frame_bias_accelerations", (len(self.frames), 6), q, p, v)[i]
        if built == reference:
            return acc
        T = self.frame_pose(q, frame, p)
        R, r = T[:3, :3], T[:3, 3]
        w = self.frame_velocity(q, v, frame, "local_world_aligned", p)[3:]
        a, alpha = acc[:3], acc[3:]
        if built == "local":
            a, alpha = R @ a, R @ alpha
        elif built == "world":   # the body-fixed point at O -> the frame's origin
            a = a + np.cross(alpha, r) + np.cross(w, np.cross(w, r))
        if reference == "local":
            return np.concatenate((R.T @ a, R.T @ alpha))
        if reference == "world":
            return np.concatenate((a - np.cross(alpha, r) - np.cross(w, np.cross(w, r)),
                                   alpha))
        return np.concatenate((a, alpha))

    def com(self, q, p=None) -> np.ndarray:
        """The centre of mass from O in E (3), as Pinocchio's ``centerOfMass``."""
        return self._kin_call("com", (3,), q, p)

    def com_jacobian(self, q, p=None) -> np.ndarray:
        """The 3 x nv Jacobian of the centre of mass in E (``jacobianCenterOfMass``)."""
        return self._kin_call("com_jacobian", (3, self.n), q, p)

    def centroidal_map(self, q, p=None) -> np.ndarray:
        """The 6 x nv centroidal momentum matrix A_g: the momentum about the centre of
        mass in E's axes is ``A_g v``, linear rows first (``computeCentroidalMap``)."""
        return self._kin_call("centroidal_momentum_matrix", (6, self.n), q, p)
