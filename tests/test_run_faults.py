"""Faults at run time are reported as faults, runs that stop early keep their data, bad command-line
input is one line with exit code 2 (--traceback shows the trace), and a bug of the package's is an
internal error (its traceback, exit code 70), not bad input."""

import json

import numpy as np
import pytest

from drake_hybrid.cli import INTERNAL_ERROR, main
from drake_hybrid.core.errors import ConfigError
from drake_hybrid.experiments.simulation import RunStopped, simulate
from drake_hybrid.experiments.sweep_point import evaluate_point
from drake_hybrid.tasks.config import dump_config
from drake_hybrid.tasks.registry import get_task

WINDOW = get_task("window-washing")


def _all_dropped(duration=0.3):
    config = WINDOW.default_config()
    config.duration = duration
    config.sensor_faults.dropout_probability = 1.0       # every sample NaN: the force is never measured
    return config


def test_a_dead_sensor_is_a_fault_not_a_zero_force_error():
    config = _all_dropped()
    with pytest.raises(RunStopped, match=r"sensor fault: the measured wrench has been non-finite since t = 0 s") as stop:
        simulate(config)
    summary, log = stop.value.result.summary, stop.value.result.log
    assert summary.status == "fault"
    # Stopped one control period after fault_time, with the log up to there.
    fault_time = config.sensor.fault_time
    assert fault_time < summary.stop_time <= fault_time + 2 * config.control_period
    assert len(log["t"]) >= int(fault_time / config.log_period) and log["t"][-1] <= summary.stop_time
    # The controller took F = F_d while blind: no force error is reported as measured.
    assert summary.final_force_error_percent is None and summary.force_settling_time_1_percent is None
    assert np.isnan(log["wrench"][-1]).all()


def test_a_short_dropout_within_fault_time_completes():
    config = WINDOW.default_config()
    config.duration = 0.3
    config.sensor_faults.dropout_times = [0.1]
    config.sensor_faults.dropout_duration = 0.02          # < fault_time (0.05 s): bridged, not a fault
    result = simulate(config)
    assert result.summary.status == "completed" and result.summary.stop_time == pytest.approx(0.3)


def test_a_sweep_point_with_a_sensor_fault_is_not_stable():
    row = evaluate_point(dump_config(_all_dropped(0.2)), continuous=False, discrete=False)
    assert row["stable_simulation"] is False and row["stable"] is False
    assert "sensor fault" in row["error"]


def test_cli_writes_the_stopped_run_and_exits_1(tmp_path, capsys):
    config_path = tmp_path / "fault.yaml"
    config_path.write_text(dump_config(_all_dropped()))
    out = tmp_path / "run"
    code = main(["simulate", "window-washing", "--config", str(config_path), "--out", str(out), "--no-progress",
                 "--no-plots"])
    assert code == 1
    error = capsys.readouterr().err
    assert "the run stopped at t = 0.05" in error and "(fault)" in error and "Traceback" not in error
    summary = json.loads((out / "summary.json").read_text())      # valid JSON (no NaN, no Infinity)
    assert summary["status"] == "fault" and np.load(out / "log.npz")["t"].size > 10


@pytest.mark.parametrize("argv, message", [
    (["simulate", "window-washing", "--duration", "inf"], "--duration must be positive and finite"),
    (["simulate", "window-washing", "--duration", "-1"], "--duration must be positive and finite"),
    (["simulate", "window-washing", "--option", "joints"], "--option takes KEY=VALUE, got 'joints'"),
    (["simulate", "window-washing", "--option", "chart=euler"], "has no option 'chart'"),
    (["simulate", "window-washing", "--html", "/nonexistent-folder/a.html"], "the folder '/nonexistent-folder'"),
    (["analyze", "window-washing", "--json", "."], "--json '.' is a directory"),
])
def test_bad_command_line_input_is_one_line_and_exit_code_2(argv, message, capsys):
    assert main(argv) == 2
    error = capsys.readouterr().err.strip()
    assert message in error and len(error.splitlines()) == 1 and error.startswith(f"drake-hybrid {argv[0]}: ")


def test_output_paths_are_refused_before_anything_runs(tmp_path, capsys):
    blocker = tmp_path / "a-file"
    blocker.write_text("")
    assert main(["simulate", "window-washing", "--out", str(blocker)]) == 2
    assert "exists and is not a directory" in capsys.readouterr().err


def test_traceback_flag_shows_the_error_itself():
    with pytest.raises(ValueError, match="--option takes KEY=VALUE"):
        main(["simulate", "window-washing", "--option", "joints", "--traceback"])


@pytest.mark.parametrize("bug", [TypeError("unsupported operand type(s) for +: 'float' and 'dict'"),
                                 KeyError("velocity_rows"), AttributeError("'dict' object has no attribute 'task'")])
def test_a_bug_is_an_internal_error_not_the_users_mistake(bug, monkeypatch, capsys):
    """A TypeError, KeyError, ... raised inside the package is a defect of the package's, whatever the input:
    its traceback, a line saying so and exit code 70 (INTERNAL_ERROR), never the one line and exit 2 of bad input
    (which only the package's typed errors and a missing file get)."""
    def broken(*args, **kwargs):
        raise bug

    monkeypatch.setattr("drake_hybrid.tasks.hooks.hook_names", broken)
    assert main(["tasks"]) == INTERNAL_ERROR == 70
    error = capsys.readouterr().err
    assert error.startswith("Traceback (most recent call last):") and "in broken" in error
    (last,) = error.strip().splitlines()[-1:]
    assert last.startswith(f"drake-hybrid tasks: internal error, a bug in drake_hybrid and not a mistake in your "
                           f"input: {type(bug).__name__}: ") and last.endswith("(please report it with the traceback "
                                                                                "above)")
    with pytest.raises(type(bug)):                                # --traceback: the error itself
        main(["tasks", "--traceback"])


@pytest.mark.parametrize("error, code, line", [
    (ConfigError("gains.velocity[0] must be positive, got -1"), 2,
     "drake-hybrid analyze: gains.velocity[0] must be positive, got -1"),
    (FileNotFoundError("no model 'pane.sdf' in models/"), 2, "drake-hybrid analyze: no model 'pane.sdf' in models/"),
    (RuntimeError("SAP failed to converge"), 1,
     "drake-hybrid analyze: RuntimeError: SAP failed to converge (run with --traceback for details)"),
    (ValueError("operands could not be broadcast together"), 1,
     "drake-hybrid analyze: ValueError: operands could not be broadcast together (run with --traceback for details)"),
])
def test_only_the_packages_own_errors_are_bad_input(error, code, line, monkeypatch, capsys):
    """Exit 2 and one line for the package's typed errors (a DrakeHybridError names the field, flag or file) and
    a missing file; any other error is not the user's mistake: exit 1 and one line naming its type."""
    def linearize(*args, **kwargs):
        raise error

    monkeypatch.setattr("drake_hybrid.analysis.linearization.linearize_continuous", linearize)
    assert main(["analyze", "window-washing", "--quiet"]) == code
    assert capsys.readouterr().err == line + "\n"
