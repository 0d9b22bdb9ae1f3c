"""Bad arguments of the path modules (core.paths, core.patterns, core.surfaces, station.path_job),
the PathSource and experiments.metrics: each class of bad input (a NaN, an infinity, a bool or a string
where a number goes, a wrong size, an empty list, a mismatch between arrays that describe the same rows,
a path too finely sampled) is a one-line typed error naming the argument, raised at the call (before
Drake: SurfacePath.evaluate(nan) used to abort the process inside Drake's trajectory)."""

import math

import numpy as np
import pytest

from pydrake.multibody.plant import MultibodyPlant

from drake_hybrid.core.errors import ArgumentError, ConfigError, DrakeHybridError, PathError
from drake_hybrid.core.paths import ForceProfile, PathLimits, SurfacePath, path_from_strokes, path_from_waypoints
from drake_hybrid.core.patterns import MAX_PATH_POINTS, raster, spiral
from drake_hybrid.core.surfaces import CylinderSurface, PlaneSurface, SphereSurface, ViewPlane
from drake_hybrid.experiments.metrics import (contact_time, last_valid, max_after, max_row_errors, row_commands,
                                              row_errors, row_scales, run_scale, settling_time)
from drake_hybrid.station.path_config import ForcePointConfig
from drake_hybrid.station.path_job import heading_of, path_on
from drake_hybrid.systems.path_source import PathSource, reference_frame, reference_rotation
from drake_hybrid.tasks.builtin.robots import add_ur5e_with_pad
from drake_hybrid.tasks.path import build_path, path_start_pose, with_path
from drake_hybrid.tasks.registry import get_task

SPHERE = SphereSurface([0.45, 0.0, 0.1], 0.15)
TOP = np.array([0.45, 0.0, 0.25])
WAYPOINTS = [TOP, SPHERE.closest_point(TOP + [0.03, 0.0, 0.0])[0]]
PLANE = PlaneSurface([0.0, 0.0, 0.0], [0.0, 0.0, 1.0])
LIMITS = PathLimits(0.05, 0.5)


def refused(call, error, *names):
    """``call()`` raises ``error`` in one line naming each of ``names``."""
    with pytest.raises(error) as raised:
        call()
    message = str(raised.value)
    assert "\n" not in message, message
    for name in names:
        assert name in message, message
    return message


@pytest.fixture(scope="module")
def path():
    return path_from_waypoints(SPHERE, WAYPOINTS, 0.02, LIMITS, 10.0, 0.002)


# ------------------------------------------------------------------------------------------------
# core.paths: evaluation, limits, offsets, forces, waypoints, strokes, holds
# ------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("t", [math.nan, math.inf, -math.inf, "1", True, None, [0.1]])
def test_evaluating_a_path_at_a_bad_time_is_a_path_error_before_drake(path, t):
    refused(lambda: path.evaluate(t), PathError, "SurfacePath.evaluate", "t must be")
    refused(lambda: path.segments[0].sample(t), PathError, "t_local")
    refused(lambda: path.force(t), PathError, "ForceProfile", "s must be")


def test_a_path_still_evaluates_before_during_and_after(path):
    assert path.evaluate(-1.0).segment == -1 and path.evaluate(1e9).segment == len(path.segments)
    assert np.all(np.isfinite(path.evaluate(np.float64(0.5 * path.duration)).velocity))


@pytest.mark.parametrize("speed, acceleration, name", [
    (True, 0.5, "speed"), ("x", 0.5, "speed"), ([0.05], 0.5, "speed"), (math.nan, 0.5, "speed"),
    (0.05, math.inf, "acceleration"), (0.05, -1.0, "acceleration"), (0.05, False, "acceleration")])
def test_bad_path_limits_are_refused_when_made(speed, acceleration, name):
    refused(lambda: PathLimits(speed, acceleration), PathError, "PathLimits", name)


@pytest.mark.parametrize("change, names", [
    (dict(offset=-0.5), ["offset", ">= 0"]), (dict(offset=math.nan), ["offset"]), (dict(offset="0.02"), ["offset"]),
    (dict(offset=True), ["offset"]), (dict(force=True), ["path.force"]), (dict(force="x"), ["path.force"]),
    (dict(force="10"), ["path.force"]), (dict(force={"a": 1}), ["path.force"]), (dict(force=math.nan), ["path.force"]),
    (dict(tolerance="x"), ["path.tolerance"]), (dict(tolerance=math.inf), ["path.tolerance"]),
    (dict(tolerance=True), ["path.tolerance"]), (dict(waypoints="abc"), ["path.waypoints"]),
    (dict(waypoints=[[0, 0, math.nan], [0, 0, 1]]), ["path.waypoints"]), (dict(limits=(0.05, 0.5)), ["limits"]),
    (dict(surface=None), ["surface"]), (dict(view="top"), ["view"]), (dict(interpolation="cubic"), ["interpolation"]),
    (dict(interpolation=None), ["interpolation"])])
def test_bad_arguments_of_path_from_waypoints(change, names):
    arguments = dict(surface=SPHERE, waypoints=WAYPOINTS, offset=0.02, limits=LIMITS, force=10.0, tolerance=0.002)
    arguments.update(change)
    refused(lambda: path_from_waypoints(**arguments), PathError, "path_from_waypoints", *names)


def test_waypoints_too_far_apart_for_one_job_are_refused_before_they_are_sampled():
    refused(lambda: path_from_waypoints(PLANE, [[0, 0, 0], [200.0, 0, 0]], 0.02, LIMITS, 10.0, 0.002), PathError,
            "path.waypoints", str(MAX_PATH_POINTS))


@pytest.mark.parametrize("strokes, name", [
    ([], "strokes"), ("abc", "strokes"), (None, "strokes"), ([[(0.0, 0.0)]], "strokes[0]"),
    ([[(0.0, 0.0), (math.nan, 0.0)]], "strokes[0]"), (np.zeros((1, 2, 3)), "strokes[0]"),
    ([[(0.0, 0.0), ("a", 0.0)]], "strokes[0]")])
def test_bad_strokes_are_refused(strokes, name):
    refused(lambda: path_from_strokes(SPHERE, SPHERE.default_view(), strokes, 0.02, LIMITS, 10.0), PathError,
            "path_from_strokes", name)


@pytest.mark.parametrize("change, name", [
    (dict(view=None), "view"), (dict(offset=-0.01), "offset"), (dict(limits=None), "limits"),
    (dict(force=True), "path.force"), (dict(surface="sphere"), "surface")])
def test_bad_arguments_of_path_from_strokes(change, name):
    arguments = dict(surface=SPHERE, view=SPHERE.default_view(), strokes=raster([0, 0], [0.02, 0.01], 0.01),
                     offset=0.02, limits=LIMITS, force=10.0)
    arguments.update(change)
    refused(lambda: path_from_strokes(**arguments), PathError, "path_from_strokes", name)


def test_an_offset_of_zero_holds_the_surface_point_itself():
    path = path_from_waypoints(PLANE, [[0, 0, 0], [0.01, 0, 0]], 0.0, LIMITS, 10.0, 1e-6)
    np.testing.assert_allclose(path.centres()[:, 2], 0.0, atol=1e-12)


@pytest.mark.parametrize("call, name", [
    (lambda: SurfacePath.hold([math.nan] * 3, [0, 0, 1], 10.0), "centre"),
    (lambda: SurfacePath.hold([0, 0, 0], [0, 0, 0], 10.0), "normal"),
    (lambda: SurfacePath.hold([0, 0], [0, 0, 1], 10.0), "centre"),
    (lambda: SurfacePath.hold([0, 0, 0], [0, 0, 1], True), "force"),
    (lambda: SurfacePath.hold([0, 0, 0], [0, 0, 1], -1.0), "force"),
    (lambda: SurfacePath([], None), "force"),
    (lambda: SurfacePath([], ForceProfile([0.0], [10.0])), "segment"),
    (lambda: SurfacePath(["segment"], ForceProfile([0.0], [10.0])), "segments[0]"),
    (lambda: ForceProfile([0.0, 1.0], [10.0, "x"]), "path.force"),
    (lambda: ForceProfile([0.0, math.nan], [10.0, 12.0]), "path.force"),
    (lambda: ForceProfile([0.0], [True]), "path.force")])
def test_bad_holds_and_force_profiles(call, name):
    refused(call, PathError, name)


def test_a_held_normal_is_made_unit():
    assert np.allclose(SurfacePath.hold([0, 0, 0], [0, 0, 2], 10.0).evaluate(0.0).normal, [0, 0, 1])


# ------------------------------------------------------------------------------------------------
# core.patterns and core.surfaces
# ------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("call, name", [
    (lambda: raster([0, 0], [0.1, 0.1], "0.02"), "pattern.spacing"),
    (lambda: raster([0, 0], [0.1, 0.1], True), "pattern.spacing"),
    (lambda: raster([0, 0], [0.1, 0.1], "x"), "pattern.spacing"),
    (lambda: raster(["a", "b"], [0.1, 0.1], 0.02), "pattern.center"),
    (lambda: raster([0, 0], [0.1, math.nan], 0.02), "pattern.size"),
    (lambda: raster([0, 0], [0.1, 0.1], 0.02, direction=None), "pattern.direction"),
    (lambda: spiral([0, 0], "0.05", 0.01), "pattern.radius"),
    (lambda: spiral([0, 0], 0.05, 0.01, step=0.0), "step"),
    (lambda: spiral([True, 0], 0.05, 0.01), "pattern.center")])
def test_bad_pattern_arguments(call, name):
    refused(call, PathError, name)


@pytest.mark.parametrize("call, name", [
    (lambda: raster([0, 0], [0.1, 0.1], 1e-5), "pattern.spacing"),
    (lambda: raster([0, 0], [1e3, 1e3], 0.5), "pattern.spacing"),
    (lambda: spiral([0, 0], 1.0, 1e-6), "pattern.spacing")])
def test_a_pattern_too_fine_for_its_region_is_refused_before_it_is_drawn(call, name):
    message = refused(call, PathError, name, str(MAX_PATH_POINTS))
    assert "too fine" in message


def test_a_pattern_within_the_bound_is_drawn():
    strokes = raster([0, 0], [0.3, 0.3], 0.01)
    assert sum(len(stroke) for stroke in strokes) < MAX_PATH_POINTS


@pytest.mark.parametrize("call, name", [
    (lambda: SphereSurface([0, 0, 0], True), "radius"), (lambda: SphereSurface([0, 0, 0], "0.1"), "radius"),
    (lambda: SphereSurface("abc", 0.1), "center"), (lambda: SphereSurface([0, 0, 0], 0.1, name=3), "name"),
    (lambda: PlaneSurface([0, 0, math.inf], [0, 0, 1]), "point"), (lambda: PlaneSurface([0, 0, 0], "z"), "normal"),
    (lambda: CylinderSurface([0, 0, 0], [0, 0, 1], 0.1, length=math.nan), "length"),
    (lambda: CylinderSurface([0, 0, 0], [0, 0, 0], 0.1), "axis"),
    (lambda: ViewPlane.make(origin=[0, 0]), "origin"),
    (lambda: SPHERE.closest_point([math.nan, 0, 0]), "p"), (lambda: PLANE.closest_point("p"), "p"),
    (lambda: SPHERE.signed_distance([0, 0]), "p"), (lambda: SPHERE.lift("view", 0.0, 0.0), "view"),
    (lambda: SPHERE.lift(SPHERE.default_view(), math.nan, 0.0), "u"),
    (lambda: SPHERE.default_view().point(0.0, "v"), "v"),
    (lambda: SPHERE.implicit(None, -0.2), "offset"), (lambda: SPHERE.held_normal(TOP, math.nan), "offset")])
def test_bad_surface_arguments(call, name):
    refused(call, PathError, name)


# ------------------------------------------------------------------------------------------------
# station.path_job
# ------------------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def polishing():
    task = get_task("surface-polishing")
    config = task.default_config()
    config.path.pattern.size = [0.04, 0.02]           # two short lines: fast to build
    return task, config


@pytest.mark.parametrize("heading", [[math.nan, 0.0, 0.0], [0.0, 0.0, 0.0], [1.0, 0.0, math.inf]])
def test_a_bad_heading_of_a_job_is_refused(polishing, heading):
    task, config = polishing
    refused(lambda: path_start_pose(task, with_path(config, heading=heading)), PathError, "path.heading")
    refused(lambda: heading_of(with_path(config, heading=heading).path, SPHERE), PathError, "path.heading")


def test_a_decreasing_force_by_arc_length_is_named(polishing):
    task, config = polishing
    bad = with_path(config, force_by_arc_length=[ForcePointConfig(0.01, 10.0), ForcePointConfig(0.005, 12.0)])
    refused(lambda: build_path(task, bad), PathError, "path.force_by_arc_length", "must not decrease")


@pytest.mark.parametrize("change, name", [
    (dict(surface=None), "surface"), (dict(offset=-0.01), "offset"), (dict(offset="0.02"), "offset"),
    (dict(settings={"speed": 0.05}), "settings")])
def test_bad_arguments_of_path_on(polishing, change, name):
    arguments = dict(surface=SPHERE, offset=0.02, settings=polishing[1].path)
    arguments.update(change)
    refused(lambda: path_on(**arguments), PathError, "path_on", name)


def test_a_bool_speed_is_refused(polishing):
    task, config = polishing
    # with_path checks the changed PathConfig like a file's (a bool is not a number) before build_path
    refused(lambda: build_path(task, with_path(config, speed=True)), ConfigError, "path.speed")


# ------------------------------------------------------------------------------------------------
# systems.path_source
# ------------------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def source_arguments(polishing):
    task, config = polishing
    plant = MultibodyPlant(0.0)
    robot = add_ur5e_with_pad(plant)
    plant.Finalize()
    return dict(plant=plant, end_effector_frame=robot.end_effector_frame,
                end_effector_point=robot.end_effector_point, constraint_space=task.constraint_space(config),
                path=build_path(task, config))


def planar_space():
    window = get_task("window-washing")
    return window.constraint_space(window.default_config())


@pytest.mark.parametrize("change, name", [
    (dict(heading=[math.nan, 0.0, 0.0]), "heading"), (dict(heading=[1.0, 0.0]), "heading"),
    (dict(heading="x"), "heading"), (dict(heading=[0.0, 0.0, 0.0]), "heading"),
    (dict(force_row=0.7), "force_row"), (dict(force_row="0"), "force_row"), (dict(force_row=True), "force_row"),
    (dict(force_row=1), "force_row"), (dict(force_row=-1), "force_row"),
    (dict(dwell=True), "dwell"), (dict(dwell=math.inf), "dwell"), (dict(dwell="x"), "dwell"),
    (dict(dwell=-0.1), "dwell"), (dict(wait_for_contact="no"), "wait_for_contact"),
    (dict(wait_for_contact=1), "wait_for_contact"), (dict(wait_for_contact=True, period=math.inf), "period"),
    (dict(wait_for_contact=True, period=-1.0), "period"), (dict(wait_for_contact=True), "period"),
    (dict(path=None), "path"), (dict(path="raster"), "path"), (dict(plant=None), "plant"),
    (dict(constraint_space=None), "constraint_space"), (dict(constraint_space=planar_space()), "constraint_space"),
    (dict(end_effector_point=[math.nan, 0.0, 0.0]), "end_effector_point"),
    (dict(end_effector_point=[0.0, 0.0]), "end_effector_point")])
def test_bad_arguments_of_a_path_source(source_arguments, change, name):
    arguments = dict(source_arguments)
    arguments.update(change)
    message = refused(lambda: PathSource(**arguments), ArgumentError, "PathSource", name)
    assert "point_in_frame" not in message


def test_a_valid_path_source_is_still_built(source_arguments):
    source = PathSource(**source_arguments, heading=[1.0, 0.0, 0.0], force_row=0, dwell=0.1, wait_for_contact=True,
                        period=0.001)
    assert source.get_contact_phase_input_port() is not None


@pytest.mark.parametrize("call, name", [
    (lambda: reference_rotation([0, 0, 1], [math.nan, 0, 0]), "heading"),
    (lambda: reference_rotation([0, 0, 0], [1, 0, 0]), "normal"),
    (lambda: reference_rotation([0, 0, 1], [0, 0, 2]), "heading"),
    (lambda: reference_frame([0, 0, 1], [0, 0, math.nan], np.zeros(3), [1, 0, 0]), "normal_rate"),
    (lambda: reference_frame([0, 0, 1], np.zeros(3), np.zeros(2), [1, 0, 0]), "normal_acceleration")])
def test_bad_reference_frames(call, name):
    refused(call, ArgumentError, name)


# ------------------------------------------------------------------------------------------------
# experiments.metrics
# ------------------------------------------------------------------------------------------------

T = np.linspace(0.0, 1.0, 11)
E = np.exp(-5 * T)
E3 = np.column_stack([E, 2 * E, 3 * E])


@pytest.mark.parametrize("call, name", [
    (lambda: settling_time(T, E, math.nan), "bound"), (lambda: settling_time(T, E, -1.0), "bound"),
    (lambda: settling_time(T, E, "0.01"), "bound"), (lambda: settling_time([], [], 0.1), "times"),
    (lambda: settling_time(T, E[:5], 0.1), "error_norm"), (lambda: settling_time(T[::-1], E, 0.1), "times"),
    (lambda: settling_time(T, np.full(11, math.nan), 0.1), "error_norm"),
    (lambda: max_row_errors(T, E3, np.ones((11, 2)), 0.5), "desired"),
    (lambda: max_row_errors(T, E3, np.ones((11, 3)), 0.5, units=["m/s"]), "units"),
    (lambda: max_row_errors(T, E3, np.ones((11, 3)), math.nan), "after"),
    (lambda: max_row_errors(T[:5], E3, np.ones((11, 3)), 0.5), "error"),
    (lambda: max_row_errors(T, E3, np.ones((11, 3)), 0.5, fallback="none"), "fallback"),
    (lambda: row_errors(T, E3, np.ones((11, 3)), ["a", "b", "c", "d"], ["m/s"] * 3, 0.0, 0.5), "names"),
    (lambda: row_errors(T, E3, np.ones((11, 3)), [], ["m/s"], 0.0, 0.5), "units"),
    (lambda: row_errors(T, E3, np.ones((11, 4)), [], ["m/s"] * 3, 0.0, 0.5), "desired"),
    (lambda: row_errors(T, E3, np.ones((11, 3)), [], ["m/s"] * 3, math.nan, 0.5), "since"),
    (lambda: row_scales(np.ones((11, 3)), ["N"]), "units"),
    (lambda: row_commands([]), "desired"), (lambda: row_commands("x"), "desired"),
    (lambda: run_scale([]), "desired"), (lambda: run_scale([[1.0, "a"]]), "desired"),
    (lambda: contact_time({}), "log"), (lambda: last_valid("x"), "values"),
    (lambda: max_after(E3, T[:5] > 0), "window")])
def test_bad_metrics_arguments(call, name):
    refused(call, ArgumentError, name)


def test_metrics_still_accept_what_a_run_logs():
    assert settling_time(T, E, 0.1) == pytest.approx(0.5)
    worst = [figure for figure, _ in max_row_errors(T, E3, np.ones((11, 3)), 0.5)]
    np.testing.assert_allclose(worst, E[5] * np.array([1.0, 2.0, 3.0]))       # every row, the worst included
    assert run_scale(np.zeros((11, 0))) == 0.0                  # a task without velocity rows
    assert max_row_errors(T, E3, np.ones((11, 3)), math.inf) == [(None, None)] * 3     # no contact: nothing late
    with_nan = E3.copy()
    with_nan[3] = math.nan                                     # a sample while the wrench was invalid
    assert len(row_errors(T, with_nan, np.ones((11, 3)), ["a"], ["m/s"] * 3, 0.0, 0.5)) == 3


def test_every_refusal_here_is_of_the_package_family():
    assert issubclass(PathError, DrakeHybridError) and issubclass(ArgumentError, DrakeHybridError)
