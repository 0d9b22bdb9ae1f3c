"""The compiled float law (control/fast_law.py) is the law of control/law.py: every output port and
diagnostic equal to 1e-12 on every built-in task in every mode, a redundant arm, random states,
near the singularity bound, in saturation and in the guarded move, and with the law's later lines
(the mechanism force, the discrete step's damping compensation, the tangential compensation)."""

import dataclasses
import warnings
from pathlib import Path

import numpy as np
import pytest

from pydrake.multibody.plant import MultibodyPlant

from drake_hybrid.control import fast_compile, fast_kernels, fast_law
from drake_hybrid.control.controller import HybridController
from drake_hybrid.control.damping import joint_damping
from drake_hybrid.control.gains import ControlMode
from drake_hybrid.control.safety import SafetyConfig
from drake_hybrid.scenario.builder import build_scenario
from drake_hybrid.tasks.registry import BUILT_IN_TASKS, TASKS
from drake_hybrid.tasks.task_file import load_task_file

pytestmark = pytest.mark.skipif(fast_kernels.NUMBA_ERROR is not None, reason="numba not available")


@pytest.fixture(autouse=True)
def compiled_at_the_first_tick():
    """These tests hold the compiled law against the generic one: each controller compiles (or loads)
    it at its first tick, instead of running the generic law while a background job compiles it."""
    previous = fast_compile.set_policy("foreground")
    yield
    fast_compile.set_policy(previous)

PORTS = ("actuation", "velocity_error", "force_error", "constraint_value", "projected_velocity", "force",
         "tangential_force")
DIAGNOSTICS = ("saturation_scale", "actuator_clipped", "smallest_singular_value", "singularity_damping",
               "wrench_valid", "contact_phase")
TOLERANCE = 1e-12
MODES = [mode.value for mode in ControlMode]
STATES = 25


class Guarded:
    approach_speed, approach_gain = 0.03, 8.0


def _task_start(name, joints=None):
    """(controller plant, frame, point, constraint space, gains, q0) of a task at its start."""
    task = TASKS[name]
    config = task.default_config()
    if joints is not None:
        config.task_parameters = dict(config.task_parameters, joints=joints)
    scenario = build_scenario(config, with_loggers=False)
    q0 = np.asarray(task.start_positions(scenario), dtype=float)
    return (scenario.controller_plant, scenario.robot.end_effector_frame, scenario.robot.end_effector_point,
            scenario.constraint_space, config.gains, q0)


@pytest.fixture(scope="module", params=sorted(BUILT_IN_TASKS) + ["window-washing-4r"])
def task(request):
    if request.param == "window-washing-4r":                    # the redundant arm (n = 4 > d = 3)
        return request.param, _task_start("window-washing", joints=4)
    return request.param, _task_start(request.param)


def _pair(start, mode, **arguments):
    plant, frame, point, space, gains, _ = start
    fast = HybridController(plant, frame, point, space, gains=gains, mode=mode, **arguments)
    generic = HybridController(plant, frame, point, space, gains=gains, mode=mode, fast_law=False, **arguments)
    assert fast.fast_law is not None and generic.fast_law is None
    return fast, generic


def _random_inputs(controller, q0, rng, spread):
    n, k, m = controller.num_joints, controller.velocity_size, controller.force_size
    wrench = rng.normal(scale=[2, 2, 2, 20, 20, 20])
    if rng.random() < 0.1:
        wrench[rng.integers(6)] = np.nan                         # a sensor dropout
    inputs = {"estimated_state": np.concatenate([q0 + spread * rng.normal(size=n), rng.normal(scale=0.3, size=n)]),
              "measured_wrench": wrench, "desired_velocity": rng.normal(scale=0.1, size=k),
              "desired_acceleration": rng.normal(scale=0.5, size=k), "desired_force": rng.normal(-10, 5, size=m)}
    if controller.get_contact_phase_input_port() is not None:
        inputs["contact_phase"] = np.array([float(rng.integers(4))])
        inputs["approach_reference"] = rng.normal(scale=0.01, size=m)
    return inputs


def _compare(fast, generic, inputs, integrals, what):
    results = []
    for system in (fast, generic):
        context = system.CreateDefaultContext()
        for name, value in inputs.items():
            system.GetInputPort(name).FixValue(context, value)
        context.SetContinuousState(integrals)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            ports = {name: system.GetOutputPort(name).Eval(context).copy() for name in PORTS}
            ports["derivatives"] = system.EvalTimeDerivatives(context).CopyToVector()
            diagnostics = system.diagnostics(context)
        results.append((ports, diagnostics))
    (fast_ports, fast_diagnostics), (generic_ports, generic_diagnostics) = results
    law = fast.fast_law
    assert law.disabled or law.compile_seconds is not None, f"{what}: the compiled law did not run"
    for name, expected in generic_ports.items():
        scale = max(1.0, float(np.max(np.abs(expected), initial=0.0)))
        np.testing.assert_allclose(fast_ports[name], expected, rtol=TOLERANCE, atol=TOLERANCE * scale,
                                   err_msg=f"{what}: port {name}")
    for name in DIAGNOSTICS:
        expected, actual = generic_diagnostics[name], fast_diagnostics[name]
        if isinstance(expected, float) and isinstance(actual, float):
            assert actual == pytest.approx(expected, rel=1e-9, abs=1e-12), f"{what}: {name}"
        else:
            assert actual == expected, f"{what}: {name}"
    return generic_diagnostics


@pytest.mark.slow                # several seconds: not in the fast loop (-m 'not slow')
@pytest.mark.parametrize("mode", MODES)
def test_both_paths_give_every_output_at_random_states(task, mode, rng):
    name, start = task
    fast, generic = _pair(start, mode)
    for i in range(STATES):
        inputs = _random_inputs(fast, start[5], rng, spread=0.02)
        integrals = rng.normal(scale=0.05, size=fast.integral_state_slices()[1].stop)
        _compare(fast, generic, inputs, integrals, f"{name} {mode} state {i}")
    assert fast.fast_law.fallbacks == 0


@pytest.mark.parametrize("mode", MODES)
def test_both_paths_agree_near_the_singularity_bound_in_saturation_and_off_the_surface(task, mode, rng):
    """A threshold above every sigma_min and a low bound make the damped inverse active; low effort
    limits saturate; the contact_phase input runs the guarded move in TARE, APPROACH and HOLD."""
    name, start = task
    plant = start[0]
    base_limits = np.full(plant.num_actuators(), 40.0)
    seen = {"damped": 0, "saturated": 0, "clipped": 0}
    for limits, bound in ((base_limits, 0.5), (base_limits * 0.05, 50.0), (base_limits * 0.005, 0.2)):
        safety = SafetyConfig(effort_limits=list(limits), singularity_threshold=10.0, max_joint_acceleration=bound)
        fast, generic = _pair(start, mode, safety=safety, guarded_move=Guarded())
        for i in range(8):
            inputs = _random_inputs(fast, start[5], rng, spread=0.05)
            integrals = rng.normal(scale=0.05, size=fast.integral_state_slices()[1].stop)
            diagnostics = _compare(fast, generic, inputs, integrals, f"{name} {mode} limits {limits[0]} state {i}")
            seen["damped"] += diagnostics["singularity_damping"] > 0
            seen["saturated"] += diagnostics["saturation_scale"] < 1
            seen["clipped"] += diagnostics["actuator_clipped"]
        assert fast.fast_law.fallbacks == 0
    assert all(count > 0 for count in seen.values()), seen


def _damped_start(name, start, rng, joints=None):
    """The task's controller plant rebuilt with viscous damping B in every arm joint (b in 1..20)."""
    _, _, _, space, gains, q0 = start
    task = TASKS[name if joints is None else "window-washing"]
    config = task.default_config()
    if joints is not None:
        config.task_parameters = dict(config.task_parameters, joints=joints)
    plant = MultibodyPlant(0.0)
    robot = task.add_robot(plant, config)
    for index in plant.GetJointIndices(robot.arm):
        joint = plant.get_joint(index)
        if joint.num_velocities() == 1:
            joint.set_default_damping(float(rng.uniform(1.0, 20.0)))
    plant.Finalize()
    return plant, robot.end_effector_frame, robot.end_effector_point, space, gains, q0


@pytest.mark.filterwarnings("ignore::drake_hybrid.control.damping.JointDampingWarning")
@pytest.mark.parametrize("compensate_tangential_force", [False, True])
@pytest.mark.parametrize("mode", MODES)
def test_both_paths_agree_with_the_mechanism_force_the_damping_compensation_and_the_tangential_force(
        task, mode, compensate_tangential_force, rng):
    """law.mechanism_force (an I_v, symmetric positive definite), damping.damping_compensation and, in
    impedance mode, K_0 from damping.step_task_mobility (joint damping in the model, a plant step
    h = 1 ms), law.tangential_compensation on or off and a wrench 0.8 ms late (law.measured_forces
    splits it where it was measured): the controller runs compiled (no fallback) and equals the
    generic law."""
    name, start = task
    damped = _damped_start(name, start, rng, joints=4 if name == "window-washing-4r" else None)
    assert np.all(joint_damping(damped[0]) > 0)
    k = start[3].velocity_size
    root = rng.normal(size=(k, k))
    inertia = root @ root.T + 0.1 * np.eye(k)
    fast, generic = _pair(damped, mode, velocity_row_inertia=inertia, plant_time_step=1e-3,
                          compensate_tangential_force=compensate_tangential_force, guarded_move=Guarded(),
                          wrench_lag=8e-4)
    assert fast.fast_law.ints[fast_kernels.I_MECHANISM] == 1 and fast.fast_law.ints[fast_kernels.I_DAMPING] == 1
    assert fast.fast_law.reals[fast_kernels.R_WRENCH_LAG] == 8e-4
    for i in range(4):
        inputs = _random_inputs(fast, start[5], rng, spread=0.02)
        integrals = rng.normal(scale=0.05, size=fast.integral_state_slices()[1].stop)
        _compare(fast, generic, inputs, integrals, f"{name} {mode} compensate {compensate_tangential_force} state {i}")
    assert fast.fast_law.fallbacks == 0


def test_the_first_tick_reports_its_compile_or_cache_load_time(task):
    _, start = task
    fast, _ = _pair(start, "velocity-force")
    assert fast.fast_law.compile_seconds is None               # nothing compiled at construction
    context = fast.CreateDefaultContext()
    plant = start[0]
    n = plant.num_velocities()
    fast.get_estimated_state_input_port().FixValue(context, np.concatenate([start[5], np.zeros(n)]))
    for port, size in (("measured_wrench", 6), ("desired_velocity", fast.velocity_size),
                       ("desired_acceleration", fast.velocity_size), ("desired_force", fast.force_size)):
        fast.GetInputPort(port).FixValue(context, np.zeros(size))
    fast.GetOutputPort("actuation").Eval(context)
    assert fast.fast_law.compile_seconds is not None and fast.fast_law.compile_seconds >= 0


def test_autodiff_keeps_the_generic_law(task):
    _, start = task
    fast, _ = _pair(start, "velocity-force")
    assert fast.ToAutoDiffXd().fast_law is None


def test_without_numba_the_controller_warns_once_and_runs_the_generic_law(monkeypatch):
    start = _task_start("window-washing")
    plant, frame, point, space, gains, _ = start
    monkeypatch.setattr(fast_kernels, "NUMBA_ERROR", ImportError("No module named 'numba'"))
    monkeypatch.setattr(fast_law, "_WARNED", [])
    with pytest.warns(UserWarning, match="numba unavailable") as record:
        first = HybridController(plant, frame, point, space, gains=gains)
        second = HybridController(plant, frame, point, space, gains=gains)
    assert first.fast_law is None and second.fast_law is None
    assert len([w for w in record if "numba" in str(w.message)]) == 1
    assert "\n" not in str(record[0].message)


def test_a_constraint_that_does_not_compile_leaves_the_controller_on_the_generic_law():
    start = _task_start("window-washing")
    fast, generic = _pair(start, "velocity-force")

    def fails(*arguments):
        raise TypeError("cannot compile this constraint")

    fast.fast_law._terms_into = fails
    inputs = _random_inputs(fast, start[5], np.random.default_rng(1), spread=0.01)
    context = fast.CreateDefaultContext()
    for name, value in inputs.items():
        fast.GetInputPort(name).FixValue(context, value)
    with pytest.warns(UserWarning, match="could not be compiled"):
        fast.GetOutputPort("actuation").Eval(context)
    assert fast.fast_law.disabled
    _compare(fast, generic, inputs, np.zeros(fast.integral_state_slices()[1].stop), "not compiled")


@pytest.mark.slow                # several seconds: not in the fast loop (-m 'not slow')
def test_both_paths_agree_with_an_impedance_mass(task, rng):
    """Impedance mode with a full symmetric positive definite impedance mass M_d (HybridGains.impedance_mass;
    K_0 = M_d^-1 - S on the velocity rows, law.impedance_gain): the compiled law reads M_d^-1 from its
    constants and equals the generic law."""
    name, start = task
    plant, frame, point, space, gains, q0 = start
    k = space.velocity_size
    root = rng.normal(size=(k, k))
    mass = root @ root.T + 0.5 * np.eye(k)
    heavy = dataclasses.replace(gains, impedance_mass=mass)
    fast, generic = _pair((plant, frame, point, space, heavy, q0), "impedance-force")
    offset = fast.fast_law.ints[fast_kernels.I_OFFSET_INVERSE_MASS]
    np.testing.assert_allclose(fast.fast_law.reals[offset:offset + k * k].reshape(k, k), np.linalg.inv(mass),
                               rtol=1e-12)
    for i in range(4):
        inputs = _random_inputs(fast, q0, rng, spread=0.02)
        integrals = rng.normal(scale=0.05, size=fast.integral_state_slices()[1].stop)
        _compare(fast, generic, inputs, integrals, f"{name} impedance mass state {i}")
    assert fast.fast_law.fallbacks == 0


@pytest.mark.parametrize("mode", MODES)
def test_both_paths_agree_with_a_force_damping(task, mode, rng):
    """The force rows' damping a_f = -K_fd C-dot (HybridGains.force_damping, law.force_row_damping), a full
    symmetric positive semidefinite K_fd: the compiled law reads it from its constants and equals the generic
    law, in contact and off it (where the guarded move replaces it)."""
    name, start = task
    plant, frame, point, space, gains, q0 = start
    m = space.force_size
    root = rng.normal(size=(m, m))
    damping = 20.0 * (root @ root.T) / m
    damped = dataclasses.replace(gains, force_damping=damping)
    fast, generic = _pair((plant, frame, point, space, damped, q0), mode, guarded_move=Guarded())
    offset = fast.fast_law.ints[fast_kernels.I_OFFSET_KFD]
    np.testing.assert_allclose(fast.fast_law.reals[offset:offset + m * m].reshape(m, m), damping, rtol=1e-12)
    for i in range(6):
        inputs = _random_inputs(fast, q0, rng, spread=0.02)
        integrals = rng.normal(scale=0.05, size=fast.integral_state_slices()[1].stop)
        _compare(fast, generic, inputs, integrals, f"{name} {mode} force damping state {i}")
    assert fast.fast_law.fallbacks == 0


def _first_tick(controller, start):
    context = controller.CreateDefaultContext()
    n = start[0].num_velocities()
    controller.get_estimated_state_input_port().FixValue(context, np.concatenate([start[5], np.zeros(n)]))
    for port, size in (("measured_wrench", 6), ("desired_velocity", controller.velocity_size),
                       ("desired_acceleration", controller.velocity_size), ("desired_force", controller.force_size)):
        controller.GetInputPort(port).FixValue(context, np.zeros(size))
    return controller.GetOutputPort("actuation").Eval(context).copy()


def test_a_law_not_compiled_yet_runs_generic_while_a_background_job_compiles_it(monkeypatch, tmp_path):
    """Background policy (the default): a controller whose compiled law is not on disk hands its first
    tick's signatures to one compile job and runs the generic law for its whole life (its actuation is
    the generic controller's exactly); once the job has recorded them, a new controller runs compiled."""
    monkeypatch.setenv("DRAKE_HYBRID_CACHE", str(tmp_path))
    fast_compile.set_policy("background")
    jobs = []
    monkeypatch.setattr(fast_compile, "start_job", lambda calls, module_path=None: jobs.append(calls) or 12345)
    start = _task_start("window-washing")
    fast, generic = _pair(start, "velocity-force")
    np.testing.assert_array_equal(_first_tick(fast, start), _first_tick(generic, start))
    assert fast.fast_law.compiling and fast.fast_law.compile_job == 12345 and fast.fast_law.compile_seconds is None
    (calls,) = jobs
    assert [function.py_func.__name__ for function, _ in calls] == ["terms_into", "law_from_terms",
                                                                    "finish_inverse_dynamics"]
    assert not fast_compile.compiled(calls)
    fast_compile.record(calls)                       # what the job does once numba has cached them
    later, _ = _pair(start, "velocity-force")
    _first_tick(later, start)
    assert not later.fast_law.compiling and later.fast_law.compile_seconds is not None and len(jobs) == 1


def test_a_failed_compile_job_is_reported_once_and_leaves_the_generic_law(monkeypatch, tmp_path):
    monkeypatch.setenv("DRAKE_HYBRID_CACHE", str(tmp_path))
    monkeypatch.setattr(fast_law, "_WARNED", [])
    fast_compile.set_policy("background")
    (tmp_path / "fast_law").mkdir()
    (tmp_path / "fast_law" / "failed").write_text("TypingError: no implementation\n")
    monkeypatch.setattr(fast_compile, "start_job", lambda *a, **k: pytest.fail("started a job after a failure"))
    start = _task_start("window-washing")
    fast, generic = _pair(start, "velocity-force")
    with pytest.warns(UserWarning, match="numba could not compile the fast law .TypingError"):
        np.testing.assert_array_equal(_first_tick(fast, start), _first_tick(generic, start))
    assert fast.fast_law.compiling


def test_the_compile_job_compiles_in_its_own_process_records_and_releases_its_lock(tmp_path):
    """The job itself (python -m drake_hybrid.control.fast_compile), on a small kernel and empty caches:
    it compiles the signature it is given in another process, records it, and removes its lock."""
    import os
    import subprocess
    import sys

    environment = dict(os.environ, DRAKE_HYBRID_CACHE=str(tmp_path), NUMBA_CACHE_DIR=str(tmp_path / "numba"))
    code = ("import sys, time, numpy as np\n"
            "from drake_hybrid.control import fast_compile, fast_kernels\n"
            "calls = [(fast_kernels.all_finite, fast_compile.signature_of((np.zeros(3),)))]\n"
            "assert not fast_compile.compiled(calls)\n"
            "pid = fast_compile.start_job(calls)\n"
            "assert fast_compile.start_job(calls) == pid        # one job at a time\n"
            "deadline = time.monotonic() + 120\n"
            "while fast_compile.job_running() is not None and time.monotonic() < deadline:\n"
            "    time.sleep(0.2)\n"
            "print(fast_compile.compiled(calls), fast_compile.failure())\n")
    out = subprocess.run([sys.executable, "-c", code], env=environment, capture_output=True, text=True, timeout=180)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.split() == ["True", "None"]
    folder = tmp_path / "fast_law"
    assert not (folder / "compiling.lock").exists() and not list(folder.glob("request-*"))
    assert "compiled drake_hybrid.control.fast_kernels.all_finite" in (folder / "compile.log").read_text()
    assert list((tmp_path / "numba").rglob("*.nbi"))                 # numba's own cache, written by the job


def _agree_or_raise_alike(fast, generic, inputs, integrals, what):
    """_compare, or the same ValueError from both paths (the compiled law hands a row that reads no force
    along the model's normal to the generic law, which names it)."""
    try:
        _compare(fast, generic, inputs, integrals, what)
        return True
    except ValueError as error:
        context = generic.CreateDefaultContext()
        for name, value in inputs.items():
            generic.GetInputPort(name).FixValue(context, value)
        context.SetContinuousState(integrals)
        with pytest.raises(ValueError, match="normal_force_axis='tool'") as generic_error:
            generic.GetOutputPort("actuation").Eval(context)
        assert str(error) == str(generic_error.value), what
        return False


@pytest.mark.slow                # several seconds: not in the fast loop (-m 'not slow')
@pytest.mark.parametrize("mode", MODES)
def test_both_paths_read_the_normal_row_along_the_tools_axis_alike(task, mode, rng):
    """normal_force_axis="tool" (control.normal_force): the compiled law changes the wrench along the model's
    normal itself (fast_kernels.wrench_along_tool_axis, the normal from the chart's own layout) and equals the
    generic law, which does it with the chart's task Jacobian (normal_force.model_normal), on every chart."""
    name, start = task
    plant, frame, point, space, gains, q0 = start
    fast, generic = _pair(start, mode, guarded_move=Guarded(), normal_force_axis="tool")
    assert fast.fast_law.reads_tool_axis
    agreed = 0
    for i in range(8):
        inputs = _random_inputs(fast, q0, rng, spread=0.02)
        integrals = rng.normal(scale=0.05, size=fast.integral_state_slices()[1].stop)
        agreed += _agree_or_raise_alike(fast, generic, inputs, integrals, f"{name} {mode} tool axis state {i}")
    assert agreed > 0 or name == "crank-turning", f"{name}: the normal row never read a force"


def test_the_disc_reads_its_axis_in_the_compiled_law_as_the_generic_law_does(rng):
    """The disc pressing a plane modelled 8 deg off (its normal row along the tool's axis, the disc's
    default), turned further off at random: the compiled law's wrench change equals the generic law's to
    1e-12 on every output, and the compiled law ran it (no fallback)."""
    _, config = load_task_file(Path(__file__).resolve().parents[1] / "models" / "tasks" / "disc_plane.yaml")
    scenario = build_scenario(config, with_loggers=False)
    tool = scenario.controller
    assert tool.normal_force_axis == "tool"
    arguments = {**tool._arguments, "control_period": None}
    fast = HybridController(**arguments)
    generic = HybridController(**{**arguments, "fast_law": False})
    assert fast.fast_law.reads_tool_axis and generic.fast_law is None
    q0 = np.asarray(scenario.task.start_positions(scenario), dtype=float)
    for i in range(12):
        inputs = _random_inputs(fast, q0, rng, spread=0.1)
        inputs["measured_wrench"][3:] += rng.normal(scale=20.0) * rng.normal(size=3)
        if fast.HasInputPort("path_position_error"):
            inputs["path_position_error"] = rng.normal(scale=1e-3, size=fast.velocity_size)
        integrals = rng.normal(scale=0.05, size=fast.integral_state_slices()[1].stop)
        _compare(fast, generic, inputs, integrals, f"disc state {i}")
    assert fast.fast_law.fallbacks == 0
