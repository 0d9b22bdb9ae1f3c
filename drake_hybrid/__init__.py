"""drake_hybrid: hybrid velocity/force control (Li & Sastry 1987) on Drake.

Layers (each imports only the ones above it):

* ``charts``       coordinate charts of the end-effector configuration (section 2.1)
* ``constraints``  C(r) = 0 and its derivatives E_f, E_f-dot r-dot (sections 2.2, 3.0)
* ``projections``  E_p and the constraint space E = [E_p; E_f] (sections 3.0, 3.3)
* ``kinematics``   chart quantities (r, r-dot, J, J-dot q-dot) from a MultibodyPlant
"""

from drake_hybrid.core.charts import EulerZXZChart, PlanarChart, PoseChart
from drake_hybrid.core.constraints import (Constraint, SelectingConstraint, crank_constraint, sphere_constraint,
                                           surface_constraint, window_constraint)
from drake_hybrid.core.errors import (BranchError, ChartSingularityError, ConstraintRankError, DimensionError,
                                      DrakeHybridError, GainError, KinematicSingularityWarning, OffConstraintError,
                                      UnknownVariableError)
from drake_hybrid.core.kinematics import EndEffectorKinematics, TaskKinematics
from drake_hybrid.core.projections import (ConstraintSpace, GivenVelocityProjection, KernelVelocityProjection,
                                           crank_paper_projection, crank_true_velocity_projection,
                                           sphere_paper_projection, sphere_true_velocity_projection)

__version__ = "0.1.0"
