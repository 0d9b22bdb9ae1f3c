"""Polishing a surface along a path, from the first touch to the last: a UR5e rasters a workpiece.

The job (``station.path_job``): the pad starts 5 mm above the path's first point, the contact
supervisor's guarded approach brings it down, it presses for ``path.dwell``, follows a raster
(boustrophedon) over a 10 cm x 10 cm patch seen from above at 5 cm/s and 10 N, stopping at each line
change, and lifts off at the end. Position-force mode (Remark 3) with the position error measured
against the path (``systems.path_source.PathSource``).

Workpieces (task option ``workpiece``):

``sphere``  the paper's sphere (``models/sphere_workpiece.sdf``, radius 0.15 m, as in
            sphere-polishing), the patch about its top: the surface tilts up to 25 deg from the view
            (28 deg for the pad centre's path).
``bump``    a part given as a height map (``core.height_map``): a plate with a Gaussian bump
            (3 cm high, sigma 3 cm), 41 x 41 samples over 16 cm x 16 cm.
``saddle``  a height map of the saddle z = (x^2 - y^2) / (2 x 0.25 m), 41 x 41 samples.

The constraint is the surface offset by the pad's radius (``Surface.offset_constraint``: the
distance to it, whose force is the normal force in N, and two kinematic rows holding the approach
vector along the normal); E_p the view's rows (``core.surfaces.view_projection``): the spin about a
and the pad centre's velocity along the world x and y (m/s), whose position errors are exact.

The tool is ``config.tool``: the ball pad, or a flat disc (``station.tools``), whose controlled point is the
centre of its face (the constraint then on the surface itself) and whose orientation rows are
force-controlled with zero moment (``tool.orientation``). ``model_error.workpiece_*`` moves the real
workpiece away from the surface the controller is given (``tasks.surface_model``).
"""


import numpy as np

from pydrake.math import RigidTransform
from pydrake.multibody.parsing import Parser

from drake_hybrid.control.gains import HybridGains
from drake_hybrid.control.supervision import SupervisionConfig
from drake_hybrid.core.height_map import HeightMap, HeightMapSurface
from drake_hybrid.core.surfaces import SphereSurface
from drake_hybrid.station.parsing import ConfigureParser, model_url
from drake_hybrid.station.path_config import PathConfig, PatternConfig
from drake_hybrid.station.workpieces import add_rigid_workpiece, mesh_shape
from drake_hybrid.tasks.builtin.robots import UR5E_SEED, add_ur5e_with_pad
from drake_hybrid.tasks.config import ScenarioConfig, StartConfig
from drake_hybrid.tasks.path import job_duration, path_start_positions
from drake_hybrid.tasks.surface_model import model_surface, orientation_labels, surface_constraint_space
from drake_hybrid.tasks.task import Task
from drake_hybrid.tasks.task_options import SurfacePolishingOptions

SPHERE_CENTER = np.array([0.45, 0.0, 0.10])
SPHERE_RADIUS = 0.15                                     # m, models/sphere_workpiece.sdf
MAP_CENTER = np.array([0.45, 0.0, 0.15])                 # the height maps' frame M (their z = 0)
MAP_SIZE, MAP_SAMPLES = 0.16, 41


def height_map(kind):
    """The ``bump`` or ``saddle`` HeightMap (map frame, m)."""
    x = np.linspace(-MAP_SIZE / 2, MAP_SIZE / 2, MAP_SAMPLES)
    X, Y = np.meshgrid(x, x)
    if kind == "bump":
        heights = 0.03 * np.exp(-(X ** 2 + Y ** 2) / (2 * 0.03 ** 2))
    else:
        heights = (X ** 2 - Y ** 2) / (2 * 0.25)
    return HeightMap(x, x, heights, name=f"{kind} height map")


class SurfacePolishing(Task):
    Options = SurfacePolishingOptions
    name = "surface-polishing"
    continuous_plant = True
    description = "UR5e polishing a raster over a sphere cap or a height-map part, approach to lift-off"
    camera = ((0.85, -0.6, 0.6), (0.45, 0.0, 0.2))

    def __init__(self):
        self._surfaces = {}

    def base_config(self, options):
        config = ScenarioConfig(
            task=self.name,
            mode="position-force",
            duration=20.0,
            gains=HybridGains(velocity=[30.0, 30.0, 30.0], position=[200.0, 200.0, 200.0],
                              force_proportional=[0.5, 0.0, 0.0], force_integral=[15.0, 1.0, 1.0],
                              constraint_frequency=15.0),
            start=StartConfig(in_contact=False, gap=0.005),
            supervision=SupervisionConfig(enabled=True, approach_speed=0.02, lift_height=0.01),
            task_options={"workpiece": "sphere"},
            path=PathConfig(pattern=PatternConfig(kind="raster", center=[0.0, 0.0], size=[0.1, 0.1], spacing=0.02),
                            speed=0.05, acceleration=0.5, force=10.0, dwell=0.3))
        config.task_options["workpiece"] = options.get("workpiece", "sphere")
        config.duration = job_duration(self, config)
        return config

    def labels(self, config=None):
        return {"velocity": ["spin about a", "x . c-dot", "y . c-dot"], "velocity_units": "rad/s | m/s | m/s",
                **orientation_labels(config if config is not None else self.base_config({}))}

    # -- the workpiece ---------------------------------------------------------------------------------
    def _workpiece(self, config):
        return self.options(config).workpiece

    def _real_surface(self, config):
        """The workpiece's own surface (where its geometry is)."""
        kind = self._workpiece(config)
        if kind not in self._surfaces:
            self._surfaces[kind] = (SphereSurface(SPHERE_CENTER, SPHERE_RADIUS) if kind == "sphere" else
                                    HeightMapSurface(height_map(kind), RigidTransform(MAP_CENTER)))
        return self._surfaces[kind]

    def workpiece_surface(self, config):
        """The surface the controller is given (the real one moved by the model error) and the tool's offset."""
        offset = config.tool.offset
        return model_surface(self._real_surface(config), offset, config), offset

    def real_workpiece_surface(self, config):
        return self._real_surface(config)

    def add_robot(self, plant, config):
        return add_ur5e_with_pad(plant, tool=config.tool)

    def add_workpiece(self, plant, config):
        if self._workpiece(config) == "sphere":
            parser = ConfigureParser(Parser(plant))
            sphere = parser.AddModelsFromUrl(model_url("sphere_workpiece.sdf"))[0]
            plant.WeldFrames(plant.world_frame(), plant.GetFrameByName("sphere", sphere), RigidTransform(SPHERE_CENTER))
            return list(plant.GetCollisionGeometriesForBody(plant.GetBodyByName("sphere", sphere)))
        surface = self._real_surface(config)
        return add_rigid_workpiece(plant, mesh_shape(surface, self._workpiece(config)), surface.X_WM,
                                   name=f"{self._workpiece(config)}_part", resolution_hint=0.002)

    # -- the law's task ----------------------------------------------------------------------------------
    def constraint_space(self, config):
        surface, offset = self.workpiece_surface(config)     # compiled once per surface and tool
        return surface_constraint_space(surface, offset, config)

    def start_positions(self, scenario):
        return path_start_positions(self, scenario, UR5E_SEED)
