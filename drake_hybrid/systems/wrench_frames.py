"""Where the wrench sensors' readings are: the sign convention they share, the end-effector point P
in world, and the shift of a spatial force from one point to another.

Every wrench sensor (``systems.contact_wrench_sensor``, ``systems.wrist_force_torque_sensor``)
outputs the SpatialForce [n; f] (6-vector) exerted **on the robot by the environment**, at the
end-effector point P, expressed in the world frame: the sign convention of docs/theory.md §0.
"""

import numpy as np

from drake_hybrid.core.arguments import vector
from drake_hybrid.core.errors import DimensionError


def _point_in_world(body_poses, body_index, point_in_body):
    X_WB = body_poses[int(body_index)]
    return X_WB.translation() + X_WB.rotation().matrix() @ point_in_body


def _point_in_world_floats(X_WB, point_in_body):
    """p_WP = X_WB p_BP for T = float, as a list of three floats: RigidTransform.multiply's numpy
    wrapper costs three times this arithmetic on a 3-vector (the sensors run it every step)."""
    (r00, r01, r02, t0), (r10, r11, r12, t1), (r20, r21, r22, t2) = X_WB.GetAsMatrix34().tolist()
    a, b, c = point_in_body
    return [t0 + r00 * a + r01 * b + r02 * c, t1 + r10 * a + r11 * b + r12 * c, t2 + r20 * a + r21 * b + r22 * c]


def _point(point, owner):
    return vector(point, "end_effector_point", owner, 3, unit="m", error=DimensionError)


def _shift(F_coefficients, p_from_to_W):
    """Shift a spatial force [n; f] applied at point A to point B (p_from_to = p_AB): n_B = n_A - p_AB x f."""
    n, f, p = F_coefficients[:3], F_coefficients[3:], p_from_to_W
    # p x f written out: np.cross costs ~15 us on 3-vectors in numpy 2 (benchmarks/PROFILE.md)
    return np.array([n[0] - (p[1] * f[2] - p[2] * f[1]),
                     n[1] - (p[2] * f[0] - p[0] * f[2]),
                     n[2] - (p[0] * f[1] - p[1] * f[0]),
                     f[0], f[1], f[2]])
