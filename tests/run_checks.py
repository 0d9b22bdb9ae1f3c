"""Checks on a run's summary shared by the simulation tests."""


def assert_rows_settled_within(summary, percent):
    """``summary``: a run's RunSummary. After five design time constants (from contact), every row within ``percent`` % of its own
    command; a row commanded to zero (no scale in its units) within ``percent`` % of the largest
    command of its group (velocity or force) as an absolute bound in its own units: the bound the
    former norm-based headline implied, per row. A held force row (no force loop) has no error to bound."""
    for group in ("velocity_rows", "force_rows"):
        rows = getattr(summary, group)
        largest = max(row.command for row in rows)
        for row in rows:
            if getattr(row, "held", False):
                continue                  # held by the controller: no command, no error (its figures are null)
            worst = row.max_error_after_5_time_constants
            assert worst is not None, f"{row.name}: the run ends before contact + 5 time constants"
            if row.command > 0:
                assert row.max_error_percent_after_5_time_constants < percent, row
            else:
                assert worst < percent / 100 * largest, row
