"""The docs scripts' figures are rounded to what they mean, so that rerunning them on an unchanged
tree rewrites their files byte for byte (docs/report_format.py; docs/make_baselines.py and
docs/reliability.py write through it)."""

import json
import math
import re
import sys
from pathlib import Path

import numpy as np

DOCS = Path(__file__).resolve().parents[1] / "docs"
sys.path.insert(0, str(DOCS))
from report_format import significant  # noqa: E402


def test_floats_keep_four_significant_figures_and_numerical_zeros_are_zero():
    assert significant(0.015000000000000013) == 0.015
    assert significant(3.83655935438415) == 3.837 and significant(-8.026404250250033) == -8.026
    assert significant(1.7954387976359953e-15) == 0.0 and significant(-1.1297158342076258e-11) == 0.0
    assert significant(-0.0) == 0.0 and math.copysign(1.0, significant(-1e-12)) == 1.0
    assert significant(56.48123) == 56.48 and significant(1.23456e-6) == 1.235e-6
    assert math.isnan(significant(float("nan"))) and significant(math.inf) == math.inf


def test_containers_numpy_and_other_types():
    data = {"a": [np.float64(0.1 + 0.2), (1, True)], "b": np.array([[1.0, 2.0000001]]), "c": None, "d": "text",
            "e": np.int64(7), "f": np.bool_(False)}
    assert significant(data) == {"a": [0.3, [1, True]], "b": [[1.0, 2.0]], "c": None, "d": "text", "e": 7,
                                 "f": False}
    assert json.dumps(significant(data))        # plain Python types only


def test_float_noise_below_the_kept_figures_gives_the_same_text():
    """Two runs whose figures differ in the 10th digit write the same file."""
    first = {"growth": 3.836347124517886, "fraction": 0.1391651491805575, "settling": 0.015000000000000013}
    second = {"growth": 3.8363471245179, "fraction": 0.13916514918056, "settling": 0.015}
    assert json.dumps(significant(first)) == json.dumps(significant(second))


def test_the_scripts_write_no_dates_or_run_times():
    for script in ("make_baselines.py", "reliability.py"):
        text = (DOCS / script).read_text()
        assert "significant(" in text, script
        assert "datetime" not in text and "strftime" not in text, script
    reliability = (DOCS / "reliability.py").read_text()
    assert '"wall_time"' not in reliability and "Run time per case" not in reliability


def test_make_baselines_prints_the_rounded_figures_without_float_noise():
    """docs/make_baselines.py's stdout is made from the figures as baselines.json has them: noise in the
    10th digit prints the same lines, and no number printed has more than 6 significant digits."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("make_baselines", DOCS / "make_baselines.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    tracked = json.loads((DOCS / "baselines.json").read_text())

    def noisy(value):
        if isinstance(value, dict):
            return {key: noisy(item) for key, item in value.items()}
        if isinstance(value, list):
            return [noisy(item) for item in value]
        return value * (1 + 3e-11) if isinstance(value, float) else value

    rounded = lambda results: {**significant(results), "instability": significant(results["instability"], digits=6)}
    lines = module.report_lines(rounded(noisy(tracked)))
    assert lines == module.report_lines(rounded(tracked))
    text = "\n".join(lines)
    assert "unstable fraction of the regular grid: raibert-craig" in text
    for number in re.findall(r"\d+\.\d+", text):
        assert len(number.replace(".", "").lstrip("0")) <= 6, number
