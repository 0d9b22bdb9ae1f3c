"""Stability maps and robustness sweeps, on this machine or a Dask cluster.

``run_sweep(task, spec, out_dir)`` evaluates every point of a sweep spec
(``drake_hybrid.experiments.sweep_spec``: grid and Monte Carlo over any scenario-config
field; one point: ``experiments.sweep_point.evaluate_point``) and writes one row per point to
``out_dir/results.csv`` (``experiments.sweep_results``) as soon as the point finishes, so an
interrupted or partly failed sweep keeps every finished point and ``resume=True`` runs only the
missing ones.

Execution: ``workers=N`` starts a Dask ``LocalCluster`` of N single-threaded
worker processes; ``scheduler=ADDRESS`` uses an existing Dask cluster (its
workers need drake_hybrid installed); ``workers=0`` runs in this process
without Dask (the reference the tests compare against).

Dask and distributed are the ``cluster`` extra (``pip install 'drake-hybrid[cluster]'``), imported
only by a sweep that runs on them; without it such a sweep raises ``MissingExtraError`` naming the
extra before anything is written, and ``workers=0`` runs serially as before.
"""

import copy
import json
import logging
import os
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import yaml
from tqdm import tqdm

from drake_hybrid.core.errors import MissingExtraError
from drake_hybrid.core.locks import process_alive
from drake_hybrid.experiments.config_paths import apply_parameters
from drake_hybrid.experiments.sweep_point import RESULT_COLUMNS, _stage_error, evaluate_point
from drake_hybrid.experiments.sweep_results import RESULTS_FILE, ResultsTable, _cell, _parse_cell, read_results
from drake_hybrid.experiments.sweep_spec import SweepSpecError, check_axis_values, parameters_digest
from drake_hybrid.tasks.config import dump_config
from drake_hybrid.tasks.registry import BUILT_IN_TASKS, get_task


class SweepLock:
    """``out/.lock``: one sweep at a time writes a results table. A lock whose process is gone
    (killed) is taken over; one held by a live process is a SweepSpecError naming it."""

    def __init__(self, out):
        self.path = Path(out) / ".lock"

    def __enter__(self):
        self.path.parent.mkdir(parents=True, exist_ok=True)
        for _ in range(2):
            try:
                descriptor = os.open(self.path, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
            except FileExistsError:
                holder = self._holder()
                if holder is not None and process_alive(holder):
                    raise SweepSpecError(f"{self.path.parent} is being written by another sweep (process {holder}); "
                                         "wait for it or use another output directory") from None
                self.path.unlink(missing_ok=True)    # the holder died: take the lock over
                continue
            with os.fdopen(descriptor, "w") as f:
                f.write(str(os.getpid()))
            return self
        raise SweepSpecError(f"could not take the lock {self.path}")

    def __exit__(self, *exc):
        self.path.unlink(missing_ok=True)
        return False

    def _holder(self):
        try:
            return int(self.path.read_text().strip())
        except (OSError, ValueError):
            return None


CLUSTER_EXTRA = ("sweeps on a Dask cluster need the cluster extra: pip install 'drake-hybrid[cluster]' "
                 "(or run serially: workers=0, --workers 0)")


def _dask():
    """(dask, distributed), imported here: Dask only where a sweep runs on it (tests/test_architecture.py).
    MissingExtraError (one line, naming the extra) where the cluster extra is not installed."""
    try:
        import dask
        import distributed
    except ImportError:
        raise MissingExtraError(CLUSTER_EXTRA) from None
    return dask, distributed


def _check_scheduler(address, timeout=10.0):
    """SweepSpecError (one line) if no Dask scheduler answers at ``address`` within ``timeout`` s."""
    _, distributed = _dask()
    try:
        client = distributed.Client(address, timeout=timeout)
    except (OSError, TimeoutError) as error:
        raise SweepSpecError(f"--scheduler {address}: no Dask scheduler answers there ({type(error).__name__}); "
                             "nothing was written") from None
    client.close()


@dataclass
class SweepRun:
    out_dir: Path
    results_path: Path
    points: int            # in the spec
    evaluated: int         # in this run
    failures: int          # rows with an error, in the whole table
    wall_time: float       # of this run (s)
    workers: str           # "serial", "local:N" or the scheduler address


def sweep_points(task_name, spec):
    """(base config, [(index, parameters, point config YAML)]) for ``spec`` on ``task_name``."""
    if spec.task is not None and spec.task != task_name:
        raise SweepSpecError(f"the sweep spec is for task '{spec.task}', not '{task_name}'")
    task = get_task(task_name)
    try:
        base = apply_parameters(task.default_config(), spec.base)
    except ValueError as error:
        raise SweepSpecError(f"base: {error}") from None
    check_axis_values(spec, base)              # every value given, checked like a config field
    points = []
    for index, parameters in enumerate(spec.points()):
        try:
            config = apply_parameters(base, parameters)
        except ValueError as error:
            raise SweepSpecError(f"point {index}: {error}") from None
        points.append((index, parameters, dump_config(config)))
    return base, points


def _prepare_out_dir(out, task_name, spec, base, points, resume):
    out.mkdir(parents=True, exist_ok=True)
    # The digest covers everything that changes a row: the task, every point's config and the verdicts' settings.
    settings = {"stability": asdict(spec.stability), "continuous": spec.linearize_continuous,
                "discrete": spec.linearize_discrete}
    manifest = {"task": task_name, "points": len(points),
                "digest": parameters_digest([task_name, settings] + [[p, y] for _, p, y in points]),
                "parameters": spec.paths}
    manifest_path = out / "manifest.json"
    results_path = out / RESULTS_FILE
    if results_path.exists() and not resume:
        raise SweepSpecError(f"{results_path} exists: pass --resume to continue it, "
                             "or choose another output directory")
    if resume and results_path.exists() and not manifest_path.exists():
        raise SweepSpecError(f"--resume: {out} has results but no manifest.json, so its sweep cannot be checked; "
                             "use another output directory")
    if resume and manifest_path.exists():
        previous = json.loads(manifest_path.read_text())
        if previous.get("digest") != manifest["digest"]:
            raise SweepSpecError(f"--resume: {out} holds a different sweep ({previous.get('task')}, "
                                 f"{previous.get('points')} points, parameters {previous.get('parameters')}); "
                                 "use the same spec and task, or another output directory")
    manifest_path.write_text(json.dumps(manifest, indent=2))
    (out / "spec.yaml").write_text(yaml.safe_dump(spec.source, sort_keys=False))
    (out / "base_config.yaml").write_text(dump_config(base))
    return results_path


WORKER_MEMORY = "4GB"


def _start_client(scheduler, workers, worker_memory=WORKER_MEMORY):
    """A client of the cluster at ``scheduler``, or of a new LocalCluster of ``workers`` processes.

    Drake 1.51 never frees a diagram that holds Python LeafSystems (drake#22515,
    drake#23161): a worker grows by about 10 to 30 MB per point here. The local
    cluster's nannies therefore restart a worker whose memory passes 95 % of
    ``worker_memory`` (no spilling, no pausing: a paused worker would never
    shrink); the point it was running is run again elsewhere."""
    dask, distributed = _dask()
    if scheduler:
        return distributed.Client(scheduler), None, scheduler
    memory = {"target": False, "spill": False, "pause": False, "terminate": 0.95}
    # The nannies read the terminate threshold when they start; a restarted worker gets ``config``.
    with dask.config.set({f"distributed.worker.memory.{key}": value for key, value in memory.items()}):
        cluster = distributed.LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                           dashboard_address=":0", memory_limit=worker_memory,
                                           silence_logs=logging.ERROR, config=copy.deepcopy(dask.config.config))
    return distributed.Client(cluster), cluster, f"local:{workers}"


def run_sweep(task_name, spec, out_dir, scheduler=None, workers=2, resume=False, retry_failed=False,
              progress=True, worker_memory=WORKER_MEMORY):
    """Evaluate the points of ``spec`` missing from ``out_dir/results.csv`` and append them.

    ``workers``: worker processes of the local Dask cluster (0: this process,
    no Dask); ignored with ``scheduler`` (an existing cluster's address).
    ``resume``: continue a table from the same spec and task (checked by a
    digest of the points); ``retry_failed`` also re-runs points whose row
    has an error (the new row is appended; ``read_results`` keeps the last
    row of a point). ``worker_memory``: memory limit of each local worker
    (restarted past 95 %; see ``_start_client``)."""
    if not (isinstance(workers, int) and workers >= 0):
        raise ValueError(f"workers must be a non-negative integer, got {workers!r}")
    out = Path(out_dir)
    base, points = sweep_points(task_name, spec)
    if scheduler or workers:
        _dask()                                     # the cluster extra, before anything is written
    if scheduler:
        _check_scheduler(scheduler)                 # before anything is written
    with SweepLock(out):
        return _run_locked(task_name, spec, out, base, points, scheduler, workers, resume, retry_failed, progress,
                           worker_memory)


def _run_locked(task_name, spec, out, base, points, scheduler, workers, resume, retry_failed, progress,
                worker_memory):
    results_path = _prepare_out_dir(out, task_name, spec, base, points, resume)
    columns = ["point"] + spec.paths + RESULT_COLUMNS
    table = ResultsTable(results_path, columns)
    finished = {row["point"]: row for row in read_results(results_path)}
    expected = {index: parameters for index, parameters, _ in points}
    for index, row in finished.items():
        if index not in expected or any(_parse_cell(path, _cell(value)) != row.get(path)
                                        for path, value in expected[index].items()):
            raise SweepSpecError(f"{results_path}: the row of point {index} has parameters "
                                 f"{ {path: row.get(path) for path in spec.paths} }, not this sweep's "
                                 f"{expected.get(index)}; use another output directory")
    done = {i for i, row in finished.items() if not (retry_failed and row.get("error"))}
    pending = [p for p in points if p[0] not in done]
    failures = sum(1 for i in done if finished[i].get("error"))
    options = {"criteria": asdict(spec.stability), "continuous": spec.linearize_continuous,
               "discrete": spec.linearize_discrete}
    if task_name not in BUILT_IN_TASKS:
        options["task"] = get_task(task_name)   # a registered custom task travels with its points (cloudpickle)
    start = time.perf_counter()
    bar = tqdm(total=len(points), initial=len(done), desc=f"sweep {task_name}", unit="pt", disable=not progress,
               dynamic_ncols=True)
    bar.set_postfix(failures=failures)

    def record(index, parameters, row):
        nonlocal failures
        row = dict(row, point=index, **parameters)
        table.append(row)
        failures += bool(row.get("error"))
        bar.update(1)
        bar.set_postfix(failures=failures)

    where = "serial" if pending else "nothing to run"
    try:
        if workers == 0 and not scheduler:
            for index, parameters, config_yaml in pending:
                record(index, parameters, evaluate_point(config_yaml, **options))
        elif pending:
            _, distributed = _dask()
            client, cluster, where = _start_client(scheduler, workers, worker_memory)
            try:
                futures = {client.submit(evaluate_point, config_yaml, pure=False, **options): (index, parameters)
                           for index, parameters, config_yaml in pending}
                for future in distributed.as_completed(futures):
                    index, parameters = futures.pop(future)
                    try:
                        row = future.result()
                    except Exception as error:   # the worker died (e.g. a crash in C++): keep the point
                        row = {"error": _stage_error("worker", error)}
                    future.release()             # the worker may drop the result (a restart will not redo it)
                    record(index, parameters, row)
            finally:
                client.close()
                if cluster is not None:
                    cluster.close()
    finally:
        bar.close()
    return SweepRun(out_dir=out, results_path=results_path, points=len(points), evaluated=len(pending),
                    failures=failures, wall_time=time.perf_counter() - start, workers=where)
