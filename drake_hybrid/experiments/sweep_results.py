"""The results table of a sweep: ``results.csv``, a header, then one row per point appended and
flushed as soon as the point finishes (``ResultsTable``), so that an interrupted or partly failed
sweep keeps every finished point; ``read_results`` reads it back (a retried point's last row wins),
``column`` takes one column as numbers. The columns are a point's outputs (``experiments.sweep_point``).
"""

import csv
import math
import os
from pathlib import Path

import numpy as np

from drake_hybrid.experiments.sweep_point import TEXT_COLUMNS, VERDICT_COLUMNS
from drake_hybrid.experiments.sweep_spec import SweepSpecError

RESULTS_FILE = "results.csv"


def _cell(value):
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return ""
    if isinstance(value, (bool, np.bool_)):
        return "True" if value else "False"
    if isinstance(value, (float, np.floating)):
        return repr(float(value))            # round-trips exactly
    return str(value)


def _parse_cell(column, text):
    if text == "":
        return None
    if column in VERDICT_COLUMNS:
        return text == "True"
    if column in TEXT_COLUMNS:
        return text
    try:
        return int(text) if column == "point" else float(text)
    except ValueError:
        return text                           # a non-numeric parameter value (e.g. a mode name)


class ResultsTable:
    """``results.csv``: a header, then one row per finished point, flushed as it arrives."""

    def __init__(self, path, columns):
        self.path = Path(path)
        self.columns = list(columns)
        if self.path.exists():
            self.repair()
            with self.path.open(newline="") as f:
                header = next(csv.reader(f), None)
            if header != self.columns:
                raise SweepSpecError(f"{self.path} has columns {header}, this sweep writes {self.columns}")
        else:
            with self.path.open("w", newline="") as f:
                csv.writer(f).writerow(self.columns)

    def repair(self):
        """Drop a torn last line (a write cut off mid-row: no final newline, or too few cells); its
        point is then missing and runs again. Returns the number of lines dropped."""
        data = self.path.read_bytes()
        if not data:
            return 0
        lines = data.split(b"\n")
        dropped = 0
        if lines[-1] != b"":                     # no final newline: the last row was cut off
            lines, dropped = lines[:-1] + [b""], 1
        if len(lines) > 2:
            last = next(csv.reader([lines[-2].decode(errors="replace")]), [])
            if len(last) != len(self.columns):
                lines, dropped = lines[:-2] + [b""], dropped + 1
        if dropped:
            self.path.write_bytes(b"\n".join(lines))
        return dropped

    def append(self, row):
        with self.path.open("a", newline="") as f:
            csv.writer(f).writerow([_cell(row.get(column)) for column in self.columns])
            f.flush()
            os.fsync(f.fileno())


def read_results(path):
    """The rows of a results.csv as dicts (numbers as float, verdicts as bool, empty cells as None),
    sorted by point index."""
    path = Path(path)
    if path.is_dir():
        path = path / RESULTS_FILE
    latest = {}
    with path.open(newline="") as f:
        for row in csv.DictReader(f):
            if None in row or None in row.values():   # a torn row (too many or too few cells): not a result
                continue
            row = {k: _parse_cell(k, v) for k, v in row.items()}
            latest[row["point"]] = row             # a retried point's last row wins
    return [latest[i] for i in sorted(latest)]


def column(rows, name):
    """One column of ``rows`` as a float array (None -> nan; verdicts as 1.0 / 0.0)."""
    return np.array([np.nan if row.get(name) is None else float(row[name]) for row in rows])
