"""The configuration of a run: typed dataclasses that load from and dump to YAML.

``ScenarioConfig`` embeds Drake's own configuration types where Drake has them
(``MultibodyPlantConfig`` for the plant and its contact model, ``SimulatorConfig`` for the
integrator), as the scenarios of Drake's ``manipulation`` package do, and adds what is this
package's: the task, the law's mode and gains, the pad's material, the sensor (a Union of
sensor configs chosen by YAML tag), the desired profiles, the start and the faults and
protections.

The walk from a file to a diagram::

    YAML --yaml_load_typed--> ScenarioConfig     types and names (unknown key, wrong type: ConfigError)
         --config.validate()--> checked values   every field, once, naming it (ConfigError)
         --build_scenario--> Diagram             (scenario.builder; the task's typed options resolved
                                                  by Task.options, scenario.task)

Every config dataclass validates itself with ``validate(prefix)``, raising ``ConfigError`` with
the dotted field name; ``ScenarioConfig.validate`` calls them all.
"""

import copyreg
import dataclasses
import math
import os
from dataclasses import dataclass, field
from typing import Any, Dict, List, Optional, Union

from pydrake.common.yaml import yaml_dump_typed, yaml_load_typed
from pydrake.multibody.plant import MultibodyPlantConfig
from pydrake.systems.analysis import GetIntegrationSchemes, SimulatorConfig

from drake_hybrid.control.baselines import BaselineGains
from drake_hybrid.control.gains import ControlMode, HybridGains
from drake_hybrid.control.safety import SafetyConfig
from drake_hybrid.control.supervision import SupervisionConfig
from drake_hybrid.core.arguments import instance
from drake_hybrid.core.errors import ConfigError, check_fields, check_finite
from drake_hybrid.core.schema import check_types, check_yaml_against_schema, read_yaml_file, unknown_field
from drake_hybrid.station.contact import ContactConfig, default_plant_config, validate_plant_config
from drake_hybrid.station.path_config import PathConfig
from drake_hybrid.station.sensing import ContactSensorConfig, SensorConfig, WristSensorConfig
from drake_hybrid.station.tools import ToolConfig
from drake_hybrid.systems.faults import SensorFaultConfig
from drake_hybrid.systems.sources import Profile

# The laws a scenario can close its loop with (scenario.builder): Li & Sastry's, and the baselines.
CONTROLLERS = ("li-sastry", "raibert-craig", "fisher-mujtaba", "pd-open-loop-force")


def _load_struct(schema, text):
    return yaml_load_typed(schema=schema, data=text)


def _reduce_struct(struct):
    """Pickle Drake's config structs through their YAML (pydrake 1.51 cannot pickle them), so that a
    ScenarioConfig, or a task holding one, can be shipped to Dask workers."""
    return _load_struct, (type(struct), yaml_dump_typed(struct))


for _struct in (MultibodyPlantConfig, SimulatorConfig):
    copyreg.pickle(_struct, _reduce_struct)


def validate_simulator_config(simulator: SimulatorConfig, prefix: str = "simulator.") -> None:
    """ConfigError naming the SimulatorConfig field Drake would reject or misuse."""
    if simulator.integration_scheme not in GetIntegrationSchemes():
        raise ConfigError(f"{prefix}integration_scheme must be one of {GetIntegrationSchemes()}, "
                          f"got '{simulator.integration_scheme}'")
    for name in ("max_step_size", "accuracy"):
        number = getattr(simulator, name)
        if not 0 < number < math.inf:
            raise ConfigError(f"{prefix}{name} must be positive and finite, got {number}")
    if not 0 <= simulator.target_realtime_rate < math.inf:
        raise ConfigError(f"{prefix}target_realtime_rate must be >= 0 and finite (0: as fast as possible), got "
                          f"{simulator.target_realtime_rate}")
    if not simulator.start_time == 0:
        raise ConfigError(f"{prefix}start_time must be 0 (runs start at t = 0), got {simulator.start_time}")


@dataclass
class StartConfig:
    """Start of the run: where on the constraint, and the controller's initial integrals."""

    configuration: List[float] = field(default_factory=list)   # task-specific start (see the task's docs)
    in_contact: bool = True                      # start pressing with the desired force; else approach (supervision)
    gap: float = 0.01                            # m from the surface along the pressing direction when not in contact
    tolerance: float = 5.0e-3                    # max |C(r)| allowed at the start (units of C's rows)
    force_integral: List[float] = field(default_factory=list)  # xi(0) (N s); empty = zeros
    position_error: List[float] = field(default_factory=list)  # e_p(0) (m, rad); empty = zeros

    def validate(self, prefix: str = "start.") -> None:
        check_fields(self, prefix, positive=("tolerance", "gap"))


MECHANISM_SOURCES = ("none", "given", "plant")


@dataclass
class MechanismConfig:
    """The inertia of a mechanism that moves along the velocity-controlled rows (a crank's handle,
    a valve, a door), which the paper's massless constraint leaves out (controller keyword
    ``velocity_row_inertia``, I_v: k x k in the coordinates of E_p's rows).

    source: "none" (the paper's form, default), "given" (``velocity_row_inertia``: 1, k or k*k
        entries like the gains) or "plant" (the task reads it from the simulation plant at the start,
        ``Task.velocity_row_inertia``; the crank does).
    velocity_row_inertia: I_v with source "given" (kg on a translation row, kg m^2 on a rotation
        row): 1 entry (times I), k (diagonal) or k*k (row-major).
    """

    source: str = "none"
    velocity_row_inertia: List[float] = field(default_factory=list)

    def validate(self, prefix: str = "mechanism.") -> "MechanismConfig":
        if self.source not in MECHANISM_SOURCES:
            raise ConfigError(f"{prefix}source must be one of {', '.join(MECHANISM_SOURCES)}, got '{self.source}'")
        if self.source == "given" and not self.velocity_row_inertia:
            raise ConfigError(f"{prefix}velocity_row_inertia must have 1, k or k*k entries with source 'given', "
                              "got none")
        if self.source != "given" and self.velocity_row_inertia:
            raise ConfigError(f"{prefix}velocity_row_inertia is only read with source 'given', got source "
                              f"'{self.source}'")
        return self


@dataclass
class ModelErrorConfig:
    """How the simulated robot differs from the controller's model (defaults: no error).

    The scales multiply masses and rotational inertias (same shape, same centre
    of mass) of the SIMULATION plant only; the controller keeps the nominal
    model. Drake stores masses as context parameters, so ``apply_model_error``
    sets them in a plant context; ``set_initial_conditions`` does it for every
    run and linearization.

    payload_mass_scale: factor on the tool (the bodies of the robot's non-arm model instances): mass and
        rotational inertia together.
    link_mass_scale: factor on the arm's links, mass and rotational inertia together (a uniformly denser
        link: gravity changes too).
    link_inertia_scale: factor on the rotational inertia about the centre of mass of every arm link only
        (masses and centres of mass kept: gravity stays exact).
    joint_damping: viscous friction (N m s/rad) added to every arm joint (set when the plant is built).
    joint_friction: Coulomb friction tau_c (N m) in every arm joint (``faults.JointFriction``),
        regularized over ``friction_speed`` (rad/s).
    friction_speed: rad/s, the joint speed over which the Coulomb friction rises to tau_c.
    workpiece_tilt, workpiece_tilt_axis, workpiece_pivot, workpiece_shift: where the real workpiece is
        against the surface the controller is given (a task whose workpiece names its surface,
        ``Task.workpiece_surface``): the real one is the model turned by ``workpiece_tilt`` (deg) about
        ``workpiece_tilt_axis`` (a world direction) through ``workpiece_pivot`` (world, m; empty: the path's
        first point on the real surface), then moved by ``workpiece_shift`` (world, m). The simulated
        geometry stays the task's; the controller's constraint, view and path are laid on the model
        (``core.surface_moves``, ``tasks.surface_model``).
    """

    payload_mass_scale: float = 1.0
    link_mass_scale: float = 1.0
    link_inertia_scale: float = 1.0
    joint_damping: float = 0.0
    joint_friction: float = 0.0
    friction_speed: float = 0.05
    workpiece_tilt: float = 0.0                  # deg: the real workpiece turned against the controller's model
    workpiece_tilt_axis: List[float] = field(default_factory=lambda: [1.0, 0.0, 0.0])   # world direction (dimensionless)
    workpiece_pivot: List[float] = field(default_factory=list)        # m, world; empty: the path's first point
    workpiece_shift: List[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])      # m, world: then moved by it

    @property
    def workpiece_moved(self) -> bool:
        """True if the real workpiece is not where the controller's model of it is."""
        return self.workpiece_tilt != 0 or any(value != 0 for value in self.workpiece_shift)

    def validate(self, prefix: str = "model_error.") -> "ModelErrorConfig":
        for name, size in (("workpiece_tilt_axis", 3), ("workpiece_shift", 3)):
            values = getattr(self, name)
            if len(values) != size:
                raise ConfigError(f"{prefix}{name} must be [x, y, z] (world), got {values}")
        if self.workpiece_pivot and len(self.workpiece_pivot) != 3:
            raise ConfigError(f"{prefix}workpiece_pivot must be [x, y, z] (world, m) or empty (the path's first "
                              f"point), got {self.workpiece_pivot}")
        if not sum(v * v for v in self.workpiece_tilt_axis) > 0:
            raise ConfigError(f"{prefix}workpiece_tilt_axis must be a nonzero direction, got "
                              f"{self.workpiece_tilt_axis}")
        if not abs(self.workpiece_tilt) <= 90:
            raise ConfigError(f"{prefix}workpiece_tilt must be within [-90, 90] deg, got {self.workpiece_tilt}")
        return check_fields(self, prefix, positive=("payload_mass_scale", "link_mass_scale", "link_inertia_scale",
                                             "friction_speed"),
                            nonnegative=("joint_damping", "joint_friction"))


@dataclass
class ScenarioConfig:
    """Everything that defines a run. Loads from YAML (``load_config``).

    task: a built-in task's name (``drake-hybrid tasks``) or a registered one; a task file sets its own.
    mode: the law, velocity-force (3.1-12), position-force (Remark 3) or impedance-force (3.2-6).
    duration: s of simulated time.
    plant: Drake's MultibodyPlantConfig: the plant's time step (s; 0: continuous), contact model and
        discrete contact approximation (default: 1 ms, hydroelastic, SAP).
    simulator: Drake's SimulatorConfig (the integrator of a continuous plant).
    log_period: s between logged samples (log.npz).
    sensor: the wrench sensor, ``!ContactSensorConfig`` (ideal: the contact results) or
        ``!WristSensorConfig`` (a force/torque sensor in the wrist weld), and its signal path.
    desired_velocity: r-dot_pd(t), the velocity rows' command, in their units (labels.velocity_units:
        m/s on a translation row, rad/s on a rotation row), one entry per row of E_p.
    desired_force: F_d(t), the force rows' command in E_f's coordinates (N for a constraint in metres,
        N m for one in radians; F is the force on the robot along the rows of dC/dr: pressing is
        positive where C grows out of the workpiece, negative where it grows into it), one entry per row of C.
    task_parameters: a task's own numbers by name (see the task's ``Options``; m, rad, N as it says).
    task_options: a task's own words by name (``--option KEY=VALUE``).
    controller: the law closing the loop, li-sastry (HybridController) or a baseline of
        control.baselines: raibert-craig, fisher-mujtaba, pd-open-loop-force.
    tool: the pad tool (``station.tools.ToolConfig``): the ball (default) or a flat disc, and how the
        constraint's orientation rows are controlled with it; read by the tasks that mount the tool they are
        given (surface-polishing, a task file's robot).
    """

    task: str = "window-washing"
    mode: str = "velocity-force"
    duration: float = 3.0
    max_duration: float = 3600.0                 # s of simulated time a run may ask for (raise it for longer runs)
    plant: MultibodyPlantConfig = field(default_factory=default_plant_config)
    simulator: SimulatorConfig = field(default_factory=SimulatorConfig)
    control_period: float = 1.0e-3               # s, the controller's period; 0 = continuous
    log_period: float = 1.0e-3
    gains: HybridGains = field(default_factory=HybridGains)
    contact: ContactConfig = field(default_factory=ContactConfig)
    tool: ToolConfig = field(default_factory=ToolConfig)
    sensor: SensorConfig = field(default_factory=ContactSensorConfig)
    desired_velocity: Profile = field(default_factory=Profile)
    desired_force: Profile = field(default_factory=Profile)
    start: StartConfig = field(default_factory=StartConfig)
    # The task's own parameters (numbers) and options (words); their names and types are the task's
    # (``Task.Options``): ``Task.options(config)`` reads both into it, rejecting unknown names and
    # wrong types (scenario.task).
    task_parameters: Dict[str, float] = field(default_factory=dict)
    task_options: Dict[str, str] = field(default_factory=dict)
    model_error: ModelErrorConfig = field(default_factory=ModelErrorConfig)
    sensor_faults: SensorFaultConfig = field(default_factory=SensorFaultConfig)
    supervision: SupervisionConfig = field(default_factory=SupervisionConfig)
    safety: SafetyConfig = field(default_factory=SafetyConfig)
    # The law: "li-sastry" (HybridController, default) or a baseline of control.baselines
    # (control.baselines: "raibert-craig", "fisher-mujtaba", "pd-open-loop-force"), with the same ports.
    controller: str = "li-sastry"
    baseline: BaselineGains = field(default_factory=BaselineGains)
    mechanism: MechanismConfig = field(default_factory=MechanismConfig)
    compensate_tangential_force: bool = True     # cancel the measured F_v in velocity/position-force mode
    # A job's path over the workpiece (station.path_config; inactive by default): the desired motion
    # and force then come from the path (station.path_job), not from desired_velocity / desired_force.
    path: PathConfig = field(default_factory=PathConfig)

    def replace(self, **changes: Any) -> "ScenarioConfig":
        """A copy with some top-level fields changed; ConfigError (one line, as for a YAML file) for a name
        that is not a field or a value not of the field's type (``core.schema.check_types``; the values
        are checked by ``validate``)."""
        unknown = unknown_field(ScenarioConfig, changes, "the config")
        if unknown:
            raise ConfigError(unknown)
        return check_types(dataclasses.replace(self, **changes), ScenarioConfig)

    @property
    def supervised(self) -> bool:
        """True if the run has a contact supervisor: asked for, or needed by a start off the surface."""
        return bool(self.supervision.enabled or not self.start.in_contact)

    @property
    def continuous_plant(self) -> bool:
        return self.plant.time_step == 0

    def validate(self) -> "ScenarioConfig":
        """Check every field's type (by the YAML loader's rules, ``core.schema.check_types``: a config
        built or changed in Python is checked as a file is) and value, once; ConfigError naming the
        field. The gains and profiles are checked against the task's sizes by the systems that use
        them (HybridController, ProfileSource), the start by ``scenario.start.check_start``."""
        check_types(self, ScenarioConfig)
        check_finite(self, allow_infinite=ALLOWED_INFINITE)
        try:
            ControlMode.parse(self.mode)
        except ValueError:
            raise ConfigError(f"mode must be one of {[m.value for m in ControlMode]}, got '{self.mode}'") from None
        self.desired_velocity.check_kind("desired_velocity")
        self.desired_force.check_kind("desired_force")
        if not self.control_period >= 0:
            raise ConfigError(f"control_period must be >= 0 (0 means continuous), got {self.control_period}")
        check_fields(self, "", positive=("duration", "log_period"))
        if self.duration > self.max_duration:
            raise ConfigError(f"duration ({self.duration:g} s) exceeds max_duration ({self.max_duration:g} s of "
                              "simulated time); raise max_duration if such a long run is intended")
        for name in ("control_period", "log_period"):
            if getattr(self, name) >= self.duration:
                raise ConfigError(f"{name} ({getattr(self, name):g} s) must be shorter than duration "
                                  f"({self.duration:g} s)")
        validate_plant_config(self.plant)
        validate_simulator_config(self.simulator)
        self.contact.validate()
        self.tool.validate()
        if self.tool.is_disc and (self.contact.pad_modulus != ContactConfig.pad_modulus
                                  or self.contact.pad_resolution != ContactConfig.pad_resolution):
            raise ConfigError("contact.pad_modulus and contact.pad_resolution are the ball pad's; a disc has its own: "
                              "tool.modulus, tool.resolution")
        self.sensor.validate()
        if (self.compensate_tangential_force and isinstance(self.sensor, WristSensorConfig)
                and not self.sensor.compensate_tool_inertia and self.controller == "li-sastry"):
            raise ConfigError("compensate_tangential_force: true needs sensor.compensate_tool_inertia: true with a "
                              "!WristSensorConfig (the wrist sensor reports the tool's own inertia as F_v, which "
                              "the law would cancel a second time); set one of them")
        self.start.validate()
        self.model_error.validate()
        self.sensor_faults.validate()
        self.supervision.validate()
        step, period = self.plant.time_step, self.control_period
        if step > 0 and period > 0 and step > period * (1 + 1e-9):
            raise ConfigError(f"plant.time_step ({self.plant.time_step:g} s) must not exceed control_period "
                              f"({self.control_period:g} s): the controller would act on states the plant has not "
                              "stepped to")
        if not self.start.in_contact and not self.supervision.approach_speed > 0:
            raise ConfigError("supervision.approach_speed must be > 0 with start.in_contact: false (the tool "
                              "would never reach the surface)")
        if not self.start.in_contact and self.start.gap >= self.supervision.max_travel:
            raise ConfigError(f"start.gap ({self.start.gap:g} m) must be shorter than supervision.max_travel "
                              f"({self.supervision.max_travel:g}, units of C): the guarded move stops (HOLD) after "
                              "max_travel, before it reaches the surface; raise max_travel or start closer")
        self.mechanism.validate()
        self.baseline.validate()
        self.path.validate()
        if self.path.active and self.controller != "li-sastry":
            raise ConfigError(f"path: controller '{self.controller}' is a baseline; a path job needs the li-sastry law")
        if self.controller not in CONTROLLERS:
            raise ConfigError(f"controller must be one of {', '.join(CONTROLLERS)}, got '{self.controller}'")
        if self.controller != "li-sastry" and (self.mechanism.source != "none" or self.supervised):
            raise ConfigError(f"controller '{self.controller}' is a baseline without mechanism inertia or contact "
                              "supervision: use mechanism.source none and start in contact")
        sampled_parts = [name for name, used in (("supervision (or a start off the surface)", self.supervised),
                                                 ("sensor_faults", self.sensor_faults.active()),
                                                 ("sensor.condition", self.sensor.condition)) if used]
        if sampled_parts and not self.control_period > 0:
            raise ConfigError(f"{', '.join(sampled_parts)} need a sampled controller: set control_period > 0")
        if self.supervision.tare_time > 0 and not self.start.in_contact and not self.sensor.condition:
            raise ConfigError("supervision.tare_time > 0 tares the sensor in the wrench conditioner: "
                              "set sensor.condition")
        if self.continuous_plant and not self.control_period > 0 and not self.sensor.bandwidth_hz > 0:
            raise ConfigError(
                "sensor.bandwidth_hz must be > 0 with a continuous plant and a continuous controller: the contact "
                "wrench is direct feedthrough of the actuation, so plant -> sensor -> controller -> plant is an "
                "algebraic loop that the low-pass filter breaks")
        return self


def check_scenario_config(config: ScenarioConfig, owner: str) -> ScenarioConfig:
    """``config`` if it is a ScenarioConfig, else ArgumentError (one line) naming ``owner``'s argument."""
    return instance(config, "config", owner, ScenarioConfig,
                    what="a ScenarioConfig (e.g. get_task('window-washing').default_config(); from YAML: load_config)")


# Fields where inf is a meaningful value (all others must be finite numbers; NaN never).
ALLOWED_INFINITE = ("sensor.fault_time", "safety.effort_limits", "supervision.max_travel")


def load_config(path: Union[str, os.PathLike, None] = None, data: Optional[str] = None,
                defaults: Optional[ScenarioConfig] = None) -> ScenarioConfig:
    """A ScenarioConfig from a YAML file or string, on top of ``defaults``; ConfigError (one line)
    for an unknown key, a wrong type, a repeated key or an unknown sensor tag."""
    where = f"{path}: " if path else ""
    if path is not None:
        data = read_yaml_file(path, "config file")
    elif not isinstance(data, str):
        raise ConfigError(f"load_config: data must be a YAML text (a str; a ScenarioConfig is built in Python with "
                          f"ScenarioConfig(...) or config.replace(...)), got a {type(data).__name__}")
    if defaults is not None:
        check_types(defaults, ScenarioConfig, "defaults")
    parsed = check_yaml_against_schema(data, ScenarioConfig, where)
    if not isinstance(parsed, dict):
        raise ConfigError(f"{where}a config is a YAML mapping of fields (e.g. 'duration: 2.0'), got "
                          f"{type(parsed).__name__ if parsed is not None else 'nothing'}")
    try:
        return yaml_load_typed(schema=ScenarioConfig, data=data,
                               defaults=defaults if defaults is not None else ScenarioConfig())
    except (AssertionError, RuntimeError, ValueError, TypeError) as error:
        raise ConfigError(f"{where}{str(error).splitlines()[0]}") from None


def dump_config(config: ScenarioConfig) -> str:
    return yaml_dump_typed(config)
