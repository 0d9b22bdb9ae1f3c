"""Grinding: a task with real friction (docs/theory.md §5, the paper's section 3.2).

The window-washing task (planar, default) or the sphere-polishing task (6-DOF,
``task_options.workpiece = sphere``) with Coulomb friction on the pad (mu
between 0.3 and 1.0, ``contact.friction``) and, on the window, a rough patch:
a stretch of the pane with a higher mu (``task_parameters.rough_friction``
between ``rough_start`` and ``rough_end`` along x) that the pad crosses.

The paper's answer to friction is hybrid impedance/force control (3.2-6):
impedance e_p'' + K_v e_p' + K_p e_p = F_v in the tangent directions, force
control in the normal one. The default mode here is ``impedance-force``; run
``--mode velocity-force`` on the same task to compare. The log has the usual
arrays plus ``position_error`` (e_p) and ``tangential_force`` (F_v).

Friction of two geometries combines as 2 mu_1 mu_2 / (mu_1 + mu_2) in Drake;
the patch's own coefficient is chosen so that the pad on the patch sees
``rough_friction``.
"""

import math

import numpy as np

from pydrake.geometry import AddContactMaterial, AddRigidHydroelasticProperties, Box, ProximityProperties
from pydrake.math import RigidTransform
from pydrake.multibody.plant import CoulombFriction

from drake_hybrid.control.gains import ControlMode, HybridGains
from drake_hybrid.core.arguments import joint_rows
from drake_hybrid.core.errors import ConfigError
from drake_hybrid.tasks.builtin.sphere_polishing import SpherePolishing
from drake_hybrid.tasks.builtin.window_washing import WindowWashing
from drake_hybrid.tasks.task import Task
from drake_hybrid.tasks.task_options import SPHERE_ONLY, GrindingOptions, built_in_option_help

PANE_SIZE = (3.0, 0.5, 0.02)       # models/window.sdf
PANE_CENTER_X = 1.0
# SAP's linear (Kelvin-Voigt) dissipation of the pad: a damped pad, as real grinding and polishing
# pads are. Left at Drake's default, the pad's contact mode rings for about 0.2 s after each jump of
# the friction force (docs/impedance.md). Drake adds the workpiece's relaxation time (0.1 s, not set
# here) to this one, so the pair has 0.102 s. That is what damps the ringing (docs/drake_notes.md).
PAD_RELAXATION_TIME = 0.002
WORKPIECE_RELAXATION_TIME = 0.1    # Drake's default, explicit: this task's figures were measured with it


def add_window_with_rough_patch(plant, height, start, end, mu, mu_rough):
    """Three rigid hydroelastic boxes side by side (smooth, rough from ``start`` to ``end`` along x,
    smooth), lower faces at ``height``, registered on the world body; the pad on the patch sees
    ``mu_rough``, elsewhere ``mu`` (the config's contact.friction). Returns the smooth boxes' ids."""
    x_min, x_max = PANE_CENTER_X - PANE_SIZE[0] / 2, PANE_CENTER_X + PANE_SIZE[0] / 2
    if not x_min < start < end < x_max:
        raise ConfigError(f"grinding: the rough patch [{start}, {end}] must lie on the pane [{x_min}, {x_max}]")
    if mu == 0:
        mu_rough = 0.0                      # a frictionless copy (e.g. for the linearization)
    elif not 0 < mu_rough < 2 * mu:
        raise ConfigError(f"grinding: rough_friction must be in (0, 2 mu) = (0, {2 * mu}) so that a coefficient "
                         f"of the patch combines with the pad's mu = {mu} to it; got {mu_rough}")
    # 2 mu mu_patch / (mu + mu_patch) = mu_rough
    mu_patch = mu_rough * mu / (2 * mu - mu_rough) if mu > 0 else 0.0
    geometries = []
    world = plant.world_body()
    for name, (a, b), friction, color in [("pane_left", (x_min, start), mu, [0.6, 0.8, 0.95, 0.5]),
                                          ("rough_patch", (start, end), mu_patch, [0.6, 0.4, 0.2, 0.9]),
                                          ("pane_right", (end, x_max), mu, [0.6, 0.8, 0.95, 0.5])]:
        box = Box(b - a, PANE_SIZE[1], PANE_SIZE[2])
        X = RigidTransform([(a + b) / 2, 0.0, height + PANE_SIZE[2] / 2])
        properties = ProximityProperties()
        AddRigidHydroelasticProperties(properties)
        AddContactMaterial(friction=CoulombFriction(friction, friction), properties=properties)
        geometry = plant.RegisterCollisionGeometry(world, X, box, name, properties)
        plant.RegisterVisualGeometry(world, X, box, name, np.array(color))
        if name != "rough_patch":
            geometries.append(geometry)
    # The scenario sets contact.friction on the returned (smooth) geometries; the patch keeps its own.
    return geometries


def impedance_step_peak(damping, stiffness):
    """The largest |e_p'| of the unit-mass impedance e_p'' + K_v e_p' + K_p e_p = F_v (3.2-6) of one
    row (``damping`` K_v, ``stiffness`` K_p, 1/s and 1/s^2) after a unit step of F_v from rest (m/s
    per N): the impulse response (e^(r_1 t) - e^(r_2 t)) / (r_1 - r_2) of its roots r_1, r_2 (t e^(r t)
    for a double root), at its largest over ten of the slower root's time constants."""
    r_1, r_2 = np.roots([1.0, damping, stiffness]).astype(complex)
    t = np.linspace(0.0, 10.0 / min(abs(r_1.real), abs(r_2.real)), 20001)
    if abs(r_1 - r_2) < 1e-9 * abs(r_1):
        response = t * np.exp(r_1 * t)
    else:
        response = (np.exp(r_1 * t) - np.exp(r_2 * t)) / (r_1 - r_2)
    return float(np.max(np.abs(response.real)))


def friction_step_notes(t, x, x_dot_error, command, normal_force, damping, stiffness, rough_start, rough_end, mu,
                        rough_friction, inverse_mass=1.0):
    """In impedance/force mode, the x-dot error at the rough patch's edges: each edge steps the friction
    force by (rough_friction - mu) |F_n|, and the designed impedance (3.2-6) yields to the step with a
    speed error that peaks at ``impedance_step_peak`` times the step (with K_v = 40, K_p = 300 and a 4 N
    step: 0.076 m/s, 76 % of 0.1 m/s). That is the "settled" maximum of a run that crosses an edge after
    its first five design time constants: the impedance is the design, not a speed error to settle. One
    note naming the measured peak after each edge crossed (``t``, ``x`` the pad's position along the
    pane, ``x_dot_error`` its row of the velocity error, ``command`` its command in m/s) against that
    prediction; none if the pad crosses no edge. ``inverse_mass``: the row's M_d^-1 (1: the paper's unit
    mass), which scales the force the impedance yields to."""
    on_patch = (x >= rough_start) & (x <= rough_end)
    crossings = np.nonzero(np.diff(on_patch.astype(int)))[0] + 1
    if crossings.size == 0 or not command > 0:
        return []
    step = abs(rough_friction - mu) * normal_force
    predicted = impedance_step_peak(damping, stiffness) * inverse_mass * step
    force, mass = ("F_v", "") if inverse_mass == 1.0 else ("M_d^-1 F_v", f", M_d = {1.0 / inverse_mass:g}")
    measured = []
    for n, i in enumerate(crossings):
        end = crossings[n + 1] if n + 1 < crossings.size else len(t)
        j = i + int(np.argmax(np.abs(x_dot_error[i:end])))
        edge = "entering" if on_patch[i] else "leaving"
        measured.append(f"{abs(x_dot_error[j]):.3g} m/s ({100 * abs(x_dot_error[j]) / command:.0f} %) {edge} it "
                        f"(t = {t[i]:.2f} s, peak at {t[j]:.2f} s)")
    return [f"x-dot's error at the rough patch's edges is the designed impedance yielding to the friction force: "
            f"each edge steps it by ({rough_friction:g} - {mu:g}) x {normal_force:.3g} N = {step:.3g} N, and "
            f"e_p'' + K_v e_p' + K_p e_p = {force} (3.2-6; K_v = {damping:g}, K_p = {stiffness:g}{mass}) answers "
            f"with a speed "
            f"error peaking at {predicted:.3g} m/s ({100 * predicted / command:.0f} % of the command); measured "
            f"{'; '.join(measured)}. Impedance/force regulates that impedance, not the speed: these peaks are no "
            "tracking failure, and they are the x-dot row's 'settled max' whenever the pad crosses an edge after "
            "the start's transient (docs/impedance.md)"]


def pad_positions(scenario, log):
    """The pad's position x along the pane (m) at every logged state."""
    plant = scenario.controller_plant
    context = plant.CreateDefaultContext()
    x = []
    for q in joint_rows(log["q"], "log['q']", "pad_positions", plant):
        plant.SetPositions(context, q)
        x.append(scenario.controller.kinematics.evaluate(context).configuration[0])
    return np.array(x)


# How long the force loop and the pad's contact answer a step of the friction force (docs/impedance.md:
# the compliant contact rings for about 0.15 s after each edge; 0.3 s covers it), and how early it starts:
# the pad's contact patch reaches an edge before its centre does (about 15 ms at 0.1 m/s; 0.05 s covers it).
EDGE_TRANSIENT = 0.3
EDGE_LEAD = 0.05


def force_step_note(t, force_error, command, on_patch, after):
    """In impedance/force mode, the normal force's error at the rough patch's edges (``on_patch``: the
    pad on the patch, per sample): each edge steps the friction force, and the force loop answers it
    through the arm's inertia coupling, g_f = -M_f^-1 M_fp F_v (3.2-11), with the pad's contact ringing
    for about 0.15 s. One note with the peak after each edge and the largest error away from the edges
    (from ``after``, the end of the start's transient, on); None if the pad crosses no edge."""
    crossings = np.nonzero(np.diff(on_patch.astype(int)))[0] + 1
    if crossings.size == 0 or not command > 0:
        return None
    error = np.abs(force_error)
    away = t >= after
    peaks = []
    for i in crossings:
        window = (t >= t[i] - EDGE_LEAD) & (t < t[i] + EDGE_TRANSIENT)
        away &= ~window
        j = int(np.nonzero(window)[0][np.argmax(error[window])])
        peaks.append(f"{error[j]:.3g} N ({100 * error[j] / command:.1f} %) {'entering' if on_patch[i] else 'leaving'} "
                     f"it (peak at t = {t[j]:.2f} s)")
    quiet = (f"; away from the edges (t >= {after:.2f} s, {EDGE_LEAD:g} s before to {EDGE_TRANSIENT:g} s after each) at most {np.max(error[away]):.3g} N "
             f"({100 * np.max(error[away]) / command:.2f} %)") if away.any() else ""
    return (f"F's error at the rough patch's edges is the force loop answering the friction force's step through "
            f"the arm's inertia coupling, -M_f^-1 M_fp F_v (3.2-11), with the pad's contact ringing for about "
            f"0.15 s: {'; '.join(peaks)}{quiet}. These peaks are F's 'settled max' whenever the pad crosses an "
            "edge after the start's transient (docs/impedance.md)")


def rough_patch_events(t, x, rough_start, rough_end, rough_friction):
    """The span of the run the pad spends on the rough patch (for the plots and the summary)."""
    on_patch = (x >= rough_start) & (x <= rough_end)
    if not on_patch.any():
        return []
    inside = np.nonzero(on_patch)[0]
    end = inside[-1] + 1
    return [{"start": float(t[inside[0]]), "end": float(t[min(end, len(t) - 1)]),
             "label": f"pad on the rough patch (mu = {rough_friction:g})"}]


def rough_patch_notes(scenario, log, design_time_constant, rough_start, rough_end, rough_friction):
    """Where the pad is at the end relative to the rough patch (between ``rough_start`` and ``rough_end``
    along x, mu = ``rough_friction``): leaving it releases the extra friction force, a transient that
    lasts several design time constants; whether velocity/force sticks; and, in impedance/force mode,
    the speed error each edge of the patch causes against the impedance's prediction
    (``friction_step_notes``)."""
    config = scenario.config
    if "q" not in log or config.controller != "li-sastry":
        return []
    x, t = pad_positions(scenario, log), log["t"]
    notes = []
    late = t >= t[-1] - min(1.0, 0.5 * t[-1])
    command = float(np.mean(log["desired_velocity"][late, 0]))
    speed = float(np.mean(log["velocity"][late, 0]))
    if scenario.controller.mode.value == "velocity-force" and command > 0 and speed < 0.5 * command:
        notes.append(f"the pad sticks (mean x-dot {100 * speed / command:.0f} % of the command over the last "
                     f"{t[-1] - t[late][0]:.1f} s): velocity/force with this K_v would need a velocity error "
                     "larger than the command to build the friction force mu F_n, and stalls; impedance/force "
                     "(the default mode) slides (docs/impedance.md)")
    if scenario.controller.mode.value == "impedance-force":
        gains = scenario.controller.validated_gains()
        coupled = (np.count_nonzero(gains.velocity[0, 1:]) + np.count_nonzero(gains.position[0, 1:])
                   + np.count_nonzero(gains.impedance_mass[0, 1:]))
        if not coupled:            # the x-dot row's impedance is its own (diagonal gains, the default)
            notes += friction_step_notes(t, x, log["velocity_error"][:, 0], command,
                                         float(np.max(np.abs(log["desired_force"]))), float(gains.velocity[0, 0]),
                                         float(gains.position[0, 0]), rough_start, rough_end,
                                         float(config.contact.friction), rough_friction,
                                         float(gains.impedance_inverse_mass[0, 0]))
        force_command = float(np.max(np.abs(log["desired_force"][:, 0])))
        note = force_step_note(t, log["force_error"][:, 0], force_command, (x >= rough_start) & (x <= rough_end),
                               float(t[0]) + 5 * design_time_constant)
        notes += [note] if note else []
    on_patch = (x >= rough_start) & (x <= rough_end)
    where = f"rough patch (mu = {rough_friction:g}, x from {rough_start:g} to {rough_end:g} m)"
    if on_patch[-1]:
        return notes + [f"the run ends with the pad on the {where}"]
    if not on_patch.any():
        side = "before" if x[-1] < rough_start else "past"
        return notes + [f"the pad never reaches the {where}; it ends {side} it at x = {x[-1]:.3f} m"]
    left = float(t[np.nonzero(on_patch)[0][-1] + 1])
    after = float(t[-1]) - left
    if after < 5 * design_time_constant:
        steady = left + 10 * design_time_constant
        return notes + [f"the run ends {after:.2f} s ({after / design_time_constant:.1f} design time constants) "
                        f"after the pad left the {where}: the released friction force is still accelerating it, "
                        f"so x-dot's final error is that transient's; --duration {np.ceil(steady * 10) / 10:g} "
                        "ends in steady sliding"]
    return notes + [f"the run ends in steady sliding, {after:.2f} s after the pad left the {where}"]


def _current_step_wrench(config):
    """The plant's unsampled output ports: the wrench of the step about to be taken, at a second contact
    solve a step. Friction's stick and slip change the tangential force within a step, and the
    impedance's realization (3.2-11), held to 2 % on the rough patch, needs the force of the step the
    arm is in: with the last step's (Drake's sampled ports, one step old) it was 7 % off
    (docs/drake_notes.md, "Sampled plant output ports")."""
    config.plant.use_sampled_output_ports = False
    return config


class Grinding(Task):
    Options = GrindingOptions
    name = "grinding"
    continuous_plant = True
    description = "grinding with Coulomb friction and a rough patch: impedance/force vs velocity/force (section 3.2)"

    def __init__(self):
        # The base tasks read this task's options (a superset of theirs).
        self._window = WindowWashing()
        self._window.Options = GrindingOptions
        self._sphere = SpherePolishing()
        self._sphere.Options = GrindingOptions

    def options(self, config):
        """The typed options; a sphere option (``SPHERE_ONLY``) without workpiece=sphere is refused."""
        options = super().options(config)
        given = [name for name in SPHERE_ONLY if name in config.task_parameters or name in config.task_options]
        if given and options.workpiece != "sphere":
            raise ConfigError(f"task option '{given[0]}' of task 'grinding' applies only with workpiece=sphere, got "
                              f"workpiece={options.workpiece}; give workpiece=sphere too or leave '{given[0]}' out")
        return options

    def option_help(self):
        return built_in_option_help(self.name)

    def _base(self, config):
        return self._window if self.options(config).workpiece == "window" else self._sphere

    def base_config(self, options):
        """Defaults for the window (``options={"workpiece": "sphere"}``: ``sphere_config``)."""
        return self.sphere_config() if options.get("workpiece", "window") == "sphere" else self.window_config()

    def window_config(self):
        """The planar variant: the window with mu = 0.5 and a rough patch of mu = 0.9."""
        config = self._window.base_config({})
        config.task = self.name
        config.mode = "impedance-force"
        config.duration = 3.0
        # A stiff tangential impedance (roots -10 and -30 1/s) and the same K_v for velocity mode.
        config.gains = HybridGains(velocity=[40.0, 40.0], position=[300.0, 300.0], force_proportional=0.5,
                                   force_integral=15.0)
        config.contact.friction = 0.5
        config.contact.relaxation_time = PAD_RELAXATION_TIME
        config.contact.workpiece_relaxation_time = WORKPIECE_RELAXATION_TIME
        config.start.force_integral = []
        # The paper's velocity/force law against friction (docs/impedance.md compares the modes):
        # cancelling the measured friction force would hide what this task shows.
        config.compensate_tangential_force = False
        _current_step_wrench(config)
        config.task_parameters.update({"rough_friction": 0.9, "rough_start": 1.05, "rough_end": 1.15})
        config.task_options = {"workpiece": "window"}
        return config

    def sphere_config(self):
        """The 6-DOF variant: the sphere's latitude path with mu = 0.5."""
        config = _current_step_wrench(self._sphere.base_config({}))
        config.task = self.name
        config.mode = "impedance-force"
        config.gains = HybridGains(velocity=[10.0, 40.0, 40.0], position=[16.0, 300.0, 300.0],
                                   force_proportional=[0.5, 0.0, 0.0], force_integral=[15.0, 1.0, 1.0],
                                   constraint_frequency=15.0)
        config.contact.friction = 0.5
        config.contact.relaxation_time = PAD_RELAXATION_TIME
        config.contact.workpiece_relaxation_time = WORKPIECE_RELAXATION_TIME
        config.start.force_integral = []
        # The paper's velocity/force law against friction (docs/impedance.md compares the modes):
        # cancelling the measured friction force would hide what this task shows.
        config.compensate_tangential_force = False
        config.task_options.update(workpiece="sphere")
        return config

    def labels(self, config=None):
        base = self._base(config) if config is not None else self._window
        labels = dict(base.labels(config))
        if config is None or ControlMode.parse(config.mode) is ControlMode.IMPEDANCE_FORCE:
            labels["velocity_note"] = (
                "The designed response has no friction in it: from rest the tangential impedance first builds "
                "mu F_n against static friction, then the pad slides; where the friction force steps (the shaded "
                "phases) the impedance yields to it as e_p'' + K_v e_p' + K_p e_p = F_v (3.2-6) designs (run notes)")
        return labels

    def run_notes(self, scenario, log, design_time_constant):
        """Which phase of the task the run ends in. Window: where the pad is relative to the rough
        patch (leaving it releases the extra friction force, a transient that lasts several design
        time constants). Sphere: whether static friction still holds the pad, and how long it has slid
        (``sphere_phase_note``)."""
        config = scenario.config
        if "q" not in log or config.controller != "li-sastry":
            return []
        if self._base(config) is self._sphere:
            return sphere_phase_note(log) if float(config.contact.friction) > 0 else []
        options = self.options(config)
        return rough_patch_notes(scenario, log, design_time_constant, options.rough_start, options.rough_end,
                                 options.rough_friction)

    def run_events(self, scenario, log):
        """Window: the span the pad spends on the rough patch. Sphere: when static friction lets go."""
        config = scenario.config
        if "q" not in log or config.controller != "li-sastry":
            return []
        if self._base(config) is self._sphere:
            breakaway = sphere_breakaway(log) if float(config.contact.friction) > 0 else None
            return ([] if breakaway is None else [{"start": breakaway, "end": None,
                                                   "label": "static friction lets go: the pad slides"}]
                    ) + super().run_events(scenario, log)
        options = self.options(config)
        return rough_patch_events(log["t"], pad_positions(scenario, log), options.rough_start, options.rough_end,
                                  options.rough_friction)

    # -- delegated to the base task -------------------------------------------------------------
    def add_robot(self, plant, config):
        return self._base(config).add_robot(plant, config)

    def constraint_space(self, config):
        return self._base(config).constraint_space(config)

    def make_source(self, config, controller_plant, robot, constraint_space):
        return self._base(config).make_source(config, controller_plant, robot, constraint_space)

    def start_positions(self, scenario):
        return self._base(scenario.config).start_positions(scenario)

    def inverse_kinematics(self, config, *args):
        return self._window.inverse_kinematics(config, *args)

    # -- the workpiece with friction ---------------------------------------------------------
    def add_workpiece(self, plant, config):
        base = self._base(config)
        if base is self._sphere:
            return base.add_workpiece(plant, config)
        return self._add_window_with_rough_patch(plant, config)

    def _add_window_with_rough_patch(self, plant, config):
        options = self.options(config)
        return add_window_with_rough_patch(plant, options.window_height, options.rough_start, options.rough_end,
                                           float(config.contact.friction), options.rough_friction)


# Sphere, defaults (mu = 0.5, 10 N, 0.05 m/s, impedance/force), measured on an 8 s run: breakaway at
# t = 0.56 s; the normal-force error then swings (+3.9 % at t = 2.5 s, -1.7 % at 4.25 s, 0.25 s means) and
# settles near -0.7 % from about t = 5.5 s on; with contact.friction = 0 it stays below 0.02 %; at 0.01 m/s
# (breakaway at 2.8 s) it stays below 0.5 % over the next 3 s.
SPHERE_SETTLED_AFTER_SLIDING = 5.0      # s of sliding after which that swing is over (measured, above)


def sphere_phase_note(log):
    """The sphere run's phase at its end, from the log: static friction holds the pad (path speed
    below half its command) until the tangential impedance has built mu F_n, then it slides. While
    sliding, the normal-force error is the force loop's response to the friction force through the
    arm's inertia coupling, g_f = -M_f^-1 M_fp F_v (3.2-11), which changes as the arm turns along the
    path: not the design's exponential, and zero without friction."""
    t, desired = log["t"], log["desired_velocity"]
    row = int(np.argmax(np.max(np.abs(desired), axis=0)))          # the path's row (t_1 . p-dot)
    command = np.abs(desired[:, row])
    if not np.any(command > 0):
        return []
    moving = _sliding(log)
    force_command = abs(float(log["desired_force"][-1, 0]))
    error = 100 * abs(float(log["force_error"][-1, 0])) / force_command if force_command > 0 else float("nan")
    if not moving[-1]:
        return [f"the run ends with static friction holding the pad (path speed "
                f"{100 * abs(log['velocity'][-1, row]) / command[-1]:.0f} % of the command): the tangential "
                "impedance is still building the friction force mu F_n"]
    stuck = np.nonzero(~moving)[0]
    breakaway = float(t[stuck[-1] + 1]) if stuck.size else float(t[0])
    sliding = float(t[-1]) - breakaway
    note = (f"static friction held the pad until t = {breakaway:.2f} s (the tangential impedance building mu F_n), "
            f"then it slid; the run ends {sliding:.2f} s into sliding. The normal-force error there "
            f"({error:.2f} %) is the force loop's response (3.2-11) to the friction force through the arm's "
            "inertia coupling -M_f^-1 M_fp F_v, which changes as the arm turns along the path; it swings for about "
            f"{SPHERE_SETTLED_AFTER_SLIDING:g} s of sliding (README, grinding)")
    if sliding < SPHERE_SETTLED_AFTER_SLIDING:
        note += f"; --duration {math.ceil(breakaway + SPHERE_SETTLED_AFTER_SLIDING):d} ends in steady sliding"
    else:
        note += ": the run ends in steady sliding"
    return [note]


def _sliding(log):
    """Per sample: the pad moving along the path's row at half its command or more."""
    desired = log["desired_velocity"]
    row = int(np.argmax(np.max(np.abs(desired), axis=0)))
    return np.abs(log["velocity"][:, row]) >= 0.5 * np.abs(desired[:, row])


def sphere_breakaway(log):
    """When the sphere run's pad starts to slide for good (s; None if it ends held or is never commanded)."""
    if not np.any(np.abs(log["desired_velocity"]) > 0):
        return None
    moving = _sliding(log)
    if not moving[-1]:
        return None
    stuck = np.nonzero(~moving)[0]
    return float(log["t"][stuck[-1] + 1]) if stuck.size else None
