"""The command line's help against the synopsis of docs/reference/command_line.md (what a user reads)."""

import io
import re
import subprocess
import sys
from pathlib import Path

import pytest

import drake_hybrid.__main__ as entry
import drake_hybrid.cli as cli
from drake_hybrid.cli import main, make_parser
from drake_hybrid.core.errors import ConfigError
from drake_hybrid.core.progress import Stages
from drake_hybrid.experiments.sweep import SweepRun
from drake_hybrid.tasks.registry import BUILT_IN_TASKS, TASKS, get_task
from drake_hybrid.tasks.task_options import SPHERE_ONLY

README = Path(__file__).resolve().parent.parent / "README.md"
COMMAND_LINE = README.parent / "docs" / "reference" / "command_line.md"


def _subparsers(parser):
    (action,) = [a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction"]
    return action.choices


def _commands(parser=None, prefix=()):
    """{"simulate": its parser, ..., "hardware hil": its parser, ...}: every command the user types,
    a command with modes (hardware) by each of its modes."""
    commands = {}
    for name, sub in _subparsers(parser or make_parser()).items():
        nested = [a for a in sub._actions if a.__class__.__name__ == "_SubParsersAction"]
        commands.update(_commands(sub, prefix + (name,)) if nested else {" ".join(prefix + (name,)): sub})
    return commands


def _synopsis(text):
    """{command: set of --options} of the "drake-hybrid ..." lines of a document's block."""
    synopsis = {}
    for line in text.splitlines():
        if line.startswith("drake-hybrid "):
            command = " ".join(re.match(r"drake-hybrid((?: [a-z][a-z-]*)+)", line).group(1).split())
            synopsis[command] = set(re.findall(r"--[a-z][a-z-]*", line))
    return synopsis


def _readme_synopsis():
    """{command: set of --options} from the synopsis block of the command line's reference page
    (docs/reference/command_line.md, where the README's "Command line" section moved)."""
    return _synopsis(COMMAND_LINE.read_text().split("```text", 1)[1].split("```", 1)[0])


def _options(parser):
    return {o for action in parser._actions for o in action.option_strings if o.startswith("--")} - {"--help"}


def _help(capsys, argv):
    with pytest.raises(SystemExit) as exit_info:
        make_parser().parse_args(argv)
    assert exit_info.value.code == 0
    return capsys.readouterr().out


def test_top_level_help_lists_every_command_without_markup(capsys):
    text = _help(capsys, ["--help"])
    for command in _subparsers(make_parser()):
        assert re.search(rf"drake-hybrid {command}\b", text), command
    assert "``" not in text and "`" not in text


def test_readme_synopsis_has_every_command_and_option_of_the_parser():
    synopsis = _readme_synopsis()
    commands = _commands()
    assert set(synopsis) == set(commands)
    for name, sub in commands.items():
        assert synopsis[name] == _options(sub), (name, sorted(_options(sub) ^ synopsis[name]))


def test_hardware_docs_synopsis_has_every_mode_and_option_of_the_parser():
    """docs/hardware.md's "Running" block lists each mode with all its options, as the parser has them."""
    block = (README.parent / "docs" / "hardware.md").read_text().split("## Running", 1)[1].split("```", 2)[1]
    synopsis = _synopsis(block)
    hardware = {name: sub for name, sub in _commands().items() if name.startswith("hardware ")}
    assert set(synopsis) == set(hardware) == {"hardware hil", "hardware timing", "hardware run"}
    for name, sub in hardware.items():
        assert synopsis[name] == _options(sub), (name, sorted(_options(sub) ^ synopsis[name]))


@pytest.mark.parametrize("mode", ["hil", "timing", "run"])
def test_every_hardware_option_says_what_goes_there(mode):
    """Each hardware mode has a description; each option a help string, and a metavar naming what it takes
    (URL, SECONDS, FILE: not argparse's upper-cased option name) unless it is a flag or a choice."""
    parser = _commands()[f"hardware {mode}"]
    assert parser.description and len(parser.description) > 40
    for action in parser._actions:
        assert action.help, action.option_strings
        if action.nargs == 0 or action.choices:
            continue
        assert action.metavar and action.metavar != action.dest.upper(), action.option_strings


@pytest.mark.parametrize("command", ["simulate", "analyze"])
def test_option_help_lists_every_tasks_keys(capsys, command):
    """Every built-in task's options (the command line's process knows no other task), from the light
    tasks.task_options: each task's own option_help, exactly."""
    text = _help(capsys, [command, "--help"])
    for name in BUILT_IN_TASKS:
        task = TASKS[name]
        assert f"{name}:" in text
        assert "\n".join(f"    {entry}" for entry in task.option_help()) in text, name
        for entry in task.option_help():
            assert entry.split("=")[0] in text, (name, entry)
    assert "`" not in text


# What only a reader of the source needs: the module docstrings' "Size:" paragraphs, test and source
# files, reST markup, dotted module paths.
DEVELOPER_TEXT = re.compile(r"Size:|\btests/|\w\.py\b|``|\bdrake_hybrid\.\w")


@pytest.mark.parametrize("command", [None, *sorted(set(_subparsers(make_parser())) | set(_commands()))])
def test_help_texts_point_at_documents_not_source_files(capsys, command):
    text = _help(capsys, [*command.split(), "--help"] if command else ["--help"])
    assert not re.search(r"\w+/\w+\.py", text), (command, text)
    assert not DEVELOPER_TEXT.search(text), (command, DEVELOPER_TEXT.search(text).group(0))


def test_top_level_help_is_the_users_description_not_the_modules_docstring(capsys):
    """The parser's description is ``cli.DESCRIPTION``; no paragraph of cli's docstring (its notes for
    readers of the source, such as its "Size:" reason) reaches the help, and the description itself
    has none of that developer text (so that it cannot come back through a shared string)."""
    text = _help(capsys, ["--help"])
    assert cli.DESCRIPTION.strip() in text
    for paragraph in cli.__doc__.split("\n\n"):
        assert paragraph.strip() and paragraph.strip() not in text, paragraph
    assert not DEVELOPER_TEXT.search(cli.DESCRIPTION)
    assert DEVELOPER_TEXT.search(cli.__doc__)              # the pattern does catch the docstring's own text


def test_stages_print_a_line_each_with_its_time_or_nothing():
    stream = io.StringIO()
    stages = Stages(stream=stream)
    with stages("building the diagram"):
        pass
    assert re.fullmatch(r"building the diagram \.\.\. \d+\.\d s\n", stream.getvalue())
    silent = io.StringIO()
    with Stages(enabled=False, stream=silent)("anything"):
        pass
    assert silent.getvalue() == ""


def test_simulate_reports_its_setup_stages_and_quiet_silences_them(tmp_path, capsys):
    argv = ["simulate", "window-washing", "--duration", "0.02", "--no-plots", "--out", str(tmp_path / "run")]
    assert main(argv + ["--no-progress"]) == 0
    captured = capsys.readouterr()
    for stage in ("building the diagram", "solving the start", "writing"):
        assert re.search(rf"{stage}.* \.\.\. \d+\.\d s", captured.err), (stage, captured.err)
    assert "errors per row" in captured.out
    assert main(argv + ["--quiet"]) == 0
    captured = capsys.readouterr()
    assert captured.err == "" and "errors per row" in captured.out


def test_a_resumed_sweep_with_nothing_left_says_so(tmp_path, monkeypatch, capsys):
    """Not "evaluated in 0.0 s on nothing to run"."""
    done = SweepRun(out_dir=tmp_path, results_path=tmp_path / "results.csv", points=12, evaluated=0, failures=0,
                    wall_time=0.0, workers="serial")
    monkeypatch.setattr("drake_hybrid.experiments.sweep_spec.load_spec", lambda path: object())
    monkeypatch.setattr("drake_hybrid.experiments.sweep.run_sweep", lambda *args, **kwargs: done)
    monkeypatch.setattr("drake_hybrid.experiments.sweep_results.read_results", lambda path: [{"stable": True}] * 12)
    assert main(["sweep", "window-washing", "--grid", "spec.yaml", "--resume", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "nothing to run: all 12 points already in the table" in out and "0.0 s" not in out


def test_a_sweep_says_where_it_ran_in_the_command_lines_terms(tmp_path, monkeypatch, capsys):
    """Not "(local:2)": the flag that chose it, and what it is."""
    monkeypatch.setattr("drake_hybrid.experiments.sweep_spec.load_spec", lambda path: object())
    monkeypatch.setattr("drake_hybrid.experiments.sweep_results.read_results", lambda path: [{"stable": True}] * 4)
    for workers, where in (("local:2", "on 2 local Dask worker processes (--workers)"),
                           ("serial", "serially in this process (--workers 0)"),
                           ("tcp://127.0.0.1:8786", "on the Dask scheduler at tcp://127.0.0.1:8786 (--scheduler)")):
        run = SweepRun(out_dir=tmp_path, results_path=tmp_path / "results.csv", points=4, evaluated=4, failures=0,
                       wall_time=2.0, workers=workers)
        monkeypatch.setattr("drake_hybrid.experiments.sweep.run_sweep", lambda *args, run=run, **kwargs: run)
        assert main(["sweep", "window-washing", "--grid", "spec.yaml", "--out", str(tmp_path)]) == 0
        assert f"4 of 4 points evaluated in 2.0 s {where};" in capsys.readouterr().out
    assert main(["sweep", "window-washing", "--grid", "spec.yaml", "--workers", "-1"]) == 2
    assert capsys.readouterr().err == ("drake-hybrid sweep: --workers must be 0 (serial, in this process) or a number "
                                       "of local Dask worker processes, got -1\n")


@pytest.mark.parametrize("command", ["simulate", "analyze"])
def test_the_papers_sphere_rows_without_euler_angles_are_refused_when_the_options_are_read(capsys, command):
    """velocity_rows=paper is (3.3-11), written in z-x-z Euler angles: with the default chart=pose it is one
    line naming both options (exit 2) before anything is built, not a TypeError from the projection; the
    same ConfigError where a config file or a sweep's base sets the options."""
    assert main([command, "sphere-polishing", "--option", "velocity_rows=paper", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert err.startswith(f"drake-hybrid {command}: task option velocity_rows=paper")
    assert "needs chart=euler, got chart=pose; with chart=pose use velocity_rows=true" in err
    task = get_task("sphere-polishing")
    config = task.default_config({"velocity_rows": "paper", "chart": "euler"})
    config.task_options["chart"] = "pose"
    with pytest.raises(ConfigError, match=r"velocity_rows=paper .* needs chart=euler, got chart=pose"):
        task.options(config)


def test_the_entry_point_and_the_command_line_import_without_drake_numba_matplotlib_or_dask():
    """drake-hybrid's entry point (drake_hybrid.__main__) and the command line's module load none of the heavy
    modules: each command loads what it uses when it runs, so every --help answers at once."""
    code = ("import sys, drake_hybrid.__main__, drake_hybrid.cli; heavy = [m for m in ('pydrake', 'numba', "
            "'matplotlib', 'dask', 'sympy') if m in sys.modules]; print(heavy)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


@pytest.mark.parametrize("argv", [["simulate", "--help"], ["analyze", "--help"], ["sweep", "--help"],
                                  ["hardware", "hil", "--help"], ["tasks", "--help"]])
def test_a_commands_help_loads_nothing_heavy(argv):
    code = ("import sys, drake_hybrid.__main__ as entry\ntry:\n    entry.main(sys.argv[1:])\nexcept SystemExit:\n"
            "    pass\nprint([m for m in ('pydrake', 'numba', 'matplotlib', 'dask', 'sympy') if m in sys.modules])")
    out = subprocess.run([sys.executable, "-c", code, *argv], capture_output=True, text=True, check=True).stdout
    assert "usage: drake-hybrid" in out and out.strip().endswith("[]")


def test_the_entry_points_commands_are_the_parsers():
    assert set(entry.COMMANDS) == set(_subparsers(make_parser()))


def test_the_loading_line_names_what_the_command_loads_and_respects_quiet(capsys):
    """Each command's first stage line says what it loads (Dask only for sweep); --quiet silences it;
    a refused argument or a --help prints none (nothing is loaded)."""
    assert entry.main(["tasks"]) == 0
    assert re.fullmatch(r"drake-hybrid tasks: loading Drake \.\.\. \d+\.\d s\n", capsys.readouterr().err)
    assert entry.main(["simulate", "window-washing", "--option", "nope=1"]) == 2   # loads, then refuses the option
    assert re.match(r"drake-hybrid simulate: loading Drake, numba and matplotlib \.\.\. \d+\.\d s\n",
                    capsys.readouterr().err)
    for argv in (["simulate", "window-washing", "--option", "nope=1", "--quiet"],     # quiet
                 ["simulate", "window-washing", "--option", "nope=1"]):              # main itself: no line
        assert (entry.main if "--quiet" in argv else main)(argv) == 2
        assert "loading" not in capsys.readouterr().err, argv
    for argv in (["simulate", "no-such-task"], ["analyze", "--help"]):
        with pytest.raises(SystemExit):
            entry.main(argv)
        assert "loading" not in capsys.readouterr().err, argv


@pytest.mark.slow
def test_first_line_of_a_command_comes_before_pydrake_is_imported():
    """-X importtime logs every import on stderr as it happens: the stage line must precede pydrake's."""
    result = subprocess.run([sys.executable, "-X", "importtime", "-m", "drake_hybrid", "tasks"],
                            capture_output=True, text=True)
    assert result.returncode == 0, result.stderr[-2000:]
    err = result.stderr
    loading = err.find("drake-hybrid tasks: loading Drake")
    pydrake = re.search(r"\|\s+pydrake$", err, flags=re.MULTILINE)
    assert pydrake is not None and 0 <= loading < pydrake.start(), err[:2000]
    refused = subprocess.run([sys.executable, "-m", "drake_hybrid", "simulate", "no-such-task"],
                             capture_output=True, text=True)
    assert refused.returncode == 2 and "loading" not in refused.stderr and "invalid choice" in refused.stderr


def test_the_first_compile_time_is_the_readmes_measured_figure_everywhere():
    """The README's 30-65 s for numba's first compile (measured on 2 cores) is what a run's note and
    fast_law's docstring say too."""
    from drake_hybrid.control import fast_law
    from drake_hybrid.experiments import simulation

    figure = re.search(r"compiles the\s+control law with numba \((\d+-\d+) s on 2 cores", README.read_text()).group(1)
    assert f"compiling them in the background ({figure} s on 2 shared cores" in " ".join(
        fast_law.kernels_loaded.__doc__.split())
    assert f"(once, {figure} s on 2 cores)" in simulation.COMPILING_NOTE


def test_html_writes_one_animation_and_no_meshcat_info_line(tmp_path, capsys, caplog):
    """--html FILE: the animation goes to FILE only (no second copy in the run's folder), and Drake's
    "Meshcat listening for connections" INFO line is not printed; the drake logger's level is restored."""
    import logging

    html = tmp_path / "run.html"
    with caplog.at_level(logging.INFO, logger="drake"):
        assert main(["simulate", "window-washing", "--duration", "0.02", "--no-plots", "--quiet",
                     "--out", str(tmp_path / "run"), "--html", str(html)]) == 0
        assert logging.getLogger("drake").level == logging.INFO
    captured = capsys.readouterr()
    assert "Meshcat listening" not in caplog.text + captured.out + captured.err
    assert html.read_text().lstrip().lower().startswith("<!doctype html>")
    assert sorted(p.name for p in (tmp_path / "run").iterdir()) == ["config.yaml", "log.npz", "summary.json"]
    assert f"wrote {tmp_path / 'run' / 'log.npz'}" in captured.out and str(html) in captured.out


def test_top_level_help_is_answered_without_loading_drake(capsys):
    """drake-hybrid --help prints the parser's own top-level help from drake_hybrid.commands alone (a
    fraction of a second, where loading Drake, numba, matplotlib and Dask takes several)."""
    assert entry.main(["--help"]) == 0
    assert capsys.readouterr().out == make_parser().format_help()
    code = ("import sys, drake_hybrid.__main__ as entry; entry.main(['-h']); heavy = [m for m in ('pydrake', 'numba', "
            "'matplotlib', 'dask') if m in sys.modules]; print(heavy)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert "usage: drake-hybrid" in out and out.strip().endswith("[]")


def test_simulates_help_names_each_tasks_plant_and_controller_rate():
    """The top-level help's simulate line gives the rates the built-in tasks run at (the crank's plant steps
    at 0.5 ms, the others' at 1 ms; every controller at 1 ms)."""
    text = cli.COMMAND_HELP["simulate"]
    for name in TASKS:
        config = get_task(name).default_config()
        assert f"{1e-3 / config.plant.time_step:g} kHz" in text, name
        assert f"{1e-3 / config.control_period:g} kHz controller" in text, name
    assert "the crank's at 2 kHz" in text


@pytest.mark.parametrize("command", ["simulate", "analyze"])
def test_grindings_sphere_options_say_so_and_are_refused_on_the_window(capsys, command):
    """chart, path, speed, start_angle and velocity_rows steer the sphere's path: the help says they need
    workpiece=sphere, and one given on the (default) window is one line naming it (exit 2), not ignored."""
    text = _help(capsys, [command, "--help"])
    grinding = text.split("  grinding:", 1)[1].split("\n  sphere-polishing:", 1)[0]
    for name in SPHERE_ONLY:
        (line,) = [line for line in grinding.splitlines() if line.strip().startswith(f"{name}=")]
        assert line.endswith("(workpiece=sphere only)"), line
    assert not [line for line in grinding.splitlines() if "rough_friction=" in line and "sphere only" in line]
    assert main([command, "grinding", "--option", "chart=euler"]) == 2
    assert capsys.readouterr().err == (
        f"drake-hybrid {command}: task option 'chart' of task 'grinding' applies only with workpiece=sphere, got "
        "workpiece=window; give workpiece=sphere too or leave 'chart' out\n")
    config = get_task("grinding").default_config({"workpiece": "sphere", "chart": "euler"})
    assert get_task("grinding").options(config).chart == "euler"


def test_option_lists_in_errors_are_words_not_python_lists(capsys):
    assert main(["simulate", "window-washing", "--option", "nope=1"]) == 2
    assert capsys.readouterr().err == (
        "drake-hybrid simulate: task 'window-washing' has no option 'nope'; its options: joints, window_height, "
        "window_lift, window_lift_duration, window_lift_time\n")
    assert main(["simulate", "grinding", "--option", "workpiece=drum"]) == 2
    assert capsys.readouterr().err == ("drake-hybrid simulate: task option 'workpiece' of task 'grinding' must be "
                                       "one of window, sphere, got 'drum'\n")


@pytest.mark.skipif(not Path("/proc").is_dir(), reason="needs /proc, where no file can be created")
@pytest.mark.parametrize("argv, flag, path", [
    (["simulate", "window-washing", "--out", "/proc/x"], "--out", "/proc/x"),
    (["analyze", "window-washing", "--json", "/proc/x.json"], "--json", "/proc/x.json"),
    (["analyze", "window-washing", "--plot", "/proc/x.png"], "--plot", "/proc/x.png"),
    (["sweep", "window-washing", "--grid", "spec.yaml", "--out", "/proc/x"], "--out", "/proc/x")])
def test_an_output_path_that_cannot_be_written_is_named_by_its_flag(capsys, argv, flag, path):
    """/proc exists and looks writable to root, but takes no new files: the line names the flag, the path and
    the folder, not only the system's '[Errno 2] No such file or directory'."""
    assert main(argv) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and "Errno" not in error, error
    assert error.startswith(f"drake-hybrid {argv[0]}: {flag} '{path}' "), error
    assert "'/proc'" in error and "the system says:" in error, error
