"""Shared fixtures: a fixed-seed generator and small Drake arms built in code."""

import os

os.environ.setdefault("MPLBACKEND", "Agg")
# Every controller of the suite (and of the processes it starts) runs the compiled law from its first tick,
# compiled there where the machine has none yet: results must not depend on when a background compile
# finished. The background path has its own tests (tests/test_fast_law.py).
os.environ.setdefault("DRAKE_HYBRID_COMPILE", "foreground")

import numpy as np
import pytest

from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import FixedOffsetFrame, RevoluteJoint, SpatialInertia, UnitInertia


@pytest.fixture
def rng():
    return np.random.default_rng(20261122)


def make_serial_arm(axes, offsets, masses=None, time_step=0.0):
    """A finalized serial arm: joint i rotates about axes[i] (in its parent link),
    link i+1 starts at offsets[i] from link i. Returns (plant, end-effector frame)."""
    plant = MultibodyPlant(time_step)
    parent = plant.world_frame()
    masses = masses or [1.0] * len(axes)
    body = None
    for i, (axis, offset) in enumerate(zip(axes, offsets)):
        inertia = SpatialInertia(masses[i], [0.05, 0.01, -0.02], UnitInertia(0.02, 0.03, 0.025, 0.001, 0.002, -0.001))
        body = plant.AddRigidBody(f"link{i + 1}", inertia)
        X_PJ = RigidTransform(RollPitchYaw(0.1 * i, -0.2 * i, 0.3), offset)
        frame_on_parent = plant.AddFrame(
            FixedOffsetFrame(
                f"joint{i + 1}_parent", parent, X_PJ))
        plant.AddJoint(RevoluteJoint(f"joint{i + 1}", frame_on_parent, body.body_frame(), axis))
        parent = body.body_frame()
    plant.Finalize()
    return plant, body.body_frame()


@pytest.fixture
def six_dof_arm():
    axes = [[0, 0, 1], [0, 1, 0], [0, 1, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]
    offsets = [[0, 0, 0.1], [0, 0.05, 0.2], [0.4, 0, 0], [0.35, 0, 0.02], [0.1, 0.03, 0], [0.08, 0, 0.05]]
    return make_serial_arm(axes, offsets)


@pytest.fixture
def planar_arm():
    """3R arm in the world x-z plane, joints about -y (the PlanarChart's normal)."""
    axes = [[0, -1, 0]] * 3
    plant = MultibodyPlant(0.0)

    parent = plant.world_frame()
    lengths = [1.0, 0.8, 0.3]
    for i, length in enumerate(lengths):
        body = plant.AddRigidBody(f"link{i + 1}", SpatialInertia.SolidCylinderWithMass(1.0, 0.02, length, [1, 0, 0]))
        offset = [lengths[i - 1], 0, 0] if i > 0 else [0, 0, 0]
        frame = plant.AddFrame(FixedOffsetFrame(f"joint{i + 1}_parent", parent, RigidTransform(offset)))
        plant.AddJoint(RevoluteJoint(f"joint{i + 1}", frame, body.body_frame(), axes[i]))
        parent = body.body_frame()
    plant.Finalize()
    return plant, parent, np.array([lengths[-1], 0.0, 0.0])

