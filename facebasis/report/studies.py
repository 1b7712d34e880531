"""Optimisation studies over person problems: alpha, lambda, alpha x lambda, initial-weight noise,
method comparison and penetration, run in parallel on Dask and written as one results table.

Every task is a small frozen record (problem name, seed, settings); a worker builds the problem
itself (cached per worker process), so nothing large travels between processes. Each task runs
single-threaded: the parallelism is across tasks. Results come back in task order, so the table is
the same whatever the scheduling. The report module (:mod:`facebasis.report.run_report`) only reads the table.

Problems: ``default`` (the built-in face, :func:`facebasis.rigging.synthetic.default_face_problem`) and
``ict`` (``problems.generation.ict_person_problem``, needs ``../shared``).
"""

from __future__ import annotations

import csv
import dataclasses
import io
import os
import time
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from ..errors import InputError
from ..workers import available_cores

STUDIES = ("alpha", "lambda", "grid", "noise", "methods")
ALPHAS = tuple(float(a) for a in np.geomspace(0.01, 10.0, 10))
LAMBDAS = tuple(float(v) for v in np.geomspace(0.1, 1000.0, 9))
GRID_ALPHAS = tuple(float(a) for a in np.geomspace(0.01, 3.0, 6))
GRID_LAMBDAS = tuple(float(v) for v in np.geomspace(0.1, 1000.0, 5))
NOISES = (0.0, 0.1, 0.2, 0.3, 0.4, 0.5)
METHODS = ("template deltas", "deformation transfer", "vertex PCA", "example-based", "example-based + virtual edges")
COLUMNS = ("study", "problem", "seed", "method", "alpha0", "alpha1", "lam0", "lam1", "noise", "noise_seed",
           "heldout_error", "train_error", "shape_error", "rig_change", "seconds")


def _register_header() -> None:
    from ..atomic import register_csv_header

    register_csv_header(",".join(COLUMNS))  # a later `facebasis sweep --out` may replace this table


_register_header()


@dataclass(frozen=True)
class Task:
    study: str
    problem: str
    seed: int
    method: str = "example-based"
    alpha: tuple[float, float] | None = None   # None: the default schedule
    lam: tuple[float, float] | None = None
    noise: float | None = None                 # None: the problem's own rough weights
    noise_seed: int = 0


@lru_cache(maxsize=4)
def person_problem(name: str, seed: int):
    """The person problem ``name`` (default / ict) for ``seed``, cached per process."""
    if name == "default":
        from ..rigging.synthetic import default_face_problem

        return default_face_problem(seed=seed, n_train=10, n_heldout=10)
    if name == "ict":
        try:
            from problems.generation import ict_person_problem
        except ImportError as exc:  # pragma: no cover - run from the repository root
            raise InputError("problem 'ict': expected the repository's problems/ package on the path") from exc
        return ict_person_problem(seed=seed)
    raise InputError(f"problem: expected 'default' or 'ict', found {name!r}")


def _rough(pp, noise: float, noise_seed: int) -> np.ndarray:
    rng = np.random.default_rng(10_000 + noise_seed)
    return np.clip(pp.true_weights + rng.uniform(-noise, noise, pp.true_weights.shape), 0.0, 1.0)


@lru_cache(maxsize=4)
def _reference_rig(name: str, seed: int):
    """The rig generated from the true weights (noise 0): the reference of the noise study."""
    from ..rigging.problem import GenerationOptions
    from ..rigging.generation import generate_blendshapes

    pp = person_problem(name, seed)
    p = dataclasses.replace(pp.problem, initial_weights=pp.true_weights)
    return generate_blendshapes(p, GenerationOptions(threads=1)).rig


def _pca_heldout(pp) -> tuple[float, float]:
    """Vertex-space PCA baseline: the span of the training displacements (all m principal
    components), held-out expressions fitted by unconstrained least squares in it."""
    t0 = time.perf_counter()
    p = pp.problem
    D = (p.examples - p.target_neutral).reshape(len(p.examples), -1)
    _, _, Vt = np.linalg.svd(D, full_matrices=False)
    H = (pp.heldout - p.target_neutral).reshape(len(pp.heldout), -1)
    resid = H - (H @ Vt.T) @ Vt
    return float(np.linalg.norm(resid) / np.linalg.norm(H)), time.perf_counter() - t0


def run_task(task: Task) -> dict:
    """Run one task; returns one row of the results table (see :data:`COLUMNS`)."""
    from threadpoolctl import threadpool_limits

    from ..rigging.problem import GenerationOptions
    from ..rigging.heldout import heldout_error
    from ..rigging.generation import generate_blendshapes
    from ..geometry.transfer import DeformationTransfer

    with threadpool_limits(1):
        pp = person_problem(task.problem, task.seed)
        p = pp.problem
        row = {c: "" for c in COLUMNS}
        row.update(study=task.study, problem=task.problem, seed=task.seed, method=task.method,
                   noise="" if task.noise is None else task.noise, noise_seed=task.noise_seed)
        if task.noise is not None:
            p = dataclasses.replace(p, initial_weights=_rough(pp, task.noise, task.noise_seed))
        t0 = time.perf_counter()
        if task.method == "vertex PCA":
            err, secs = _pca_heldout(pp)
            row.update(heldout_error=err, train_error=0.0, seconds=secs)
            return row
        if task.method == "template deltas":
            rig = p.template.with_neutral(p.target_neutral, p.template.deltas)
        elif task.method == "deformation transfer":
            rig = DeformationTransfer(p.template, p.target_neutral).transfer()
        else:
            kw = {}
            if task.alpha is not None:
                kw["alpha"] = task.alpha
            if task.lam is not None:
                kw["lam"] = task.lam
            opts = GenerationOptions(threads=1, **kw)
            if task.method == "example-based + virtual edges":
                from ..contact.virtual_edges import detect_virtual_edges

                ve = detect_virtual_edges(p.template.neutral, p.template.faces)
                p = dataclasses.replace(p, virtual_edges=ve)
            res = generate_blendshapes(p, opts)
            rig = res.rig
            row.update(alpha0=opts.alpha[0], alpha1=opts.alpha[1], lam0=opts.lam[0], lam1=opts.lam[1])
        secs = time.perf_counter() - t0
        shape_err = np.linalg.norm(rig.deltas - pp.truth.deltas, axis=(1, 2)) / np.linalg.norm(pp.truth.deltas, axis=(1, 2))
        # held-out and training expressions measured alike: weights refitted (bounds, pairs, no prior);
        # a training error only for the methods that fit the training expressions
        fitted = task.method not in ("template deltas", "deformation transfer")
        row.update(heldout_error=heldout_error(rig, pp.heldout, p.pair_indices),
                   train_error=heldout_error(rig, p.examples, p.pair_indices) if fitted else "",
                   shape_error=float(np.median(shape_err)), seconds=secs)
        if task.study == "noise":
            ref = _reference_rig(task.problem, task.seed)
            row["rig_change"] = float(np.linalg.norm(rig.deltas - ref.deltas) / np.linalg.norm(ref.deltas))
        return row


def study_tasks(study: str, problem: str, seeds=(0,), noise_seeds=(0, 1, 2)) -> list[Task]:
    """The tasks of a study (alpha, lambda and the grid use constant schedules)."""
    seeds = tuple(int(s) for s in seeds)
    if study == "alpha":
        return [Task("alpha", problem, s, alpha=(a, a)) for s in seeds for a in ALPHAS]
    if study == "lambda":
        return [Task("lambda", problem, s, lam=(v, v)) for s in seeds for v in LAMBDAS]
    if study == "grid":
        return [Task("grid", problem, s, alpha=(a, a), lam=(v, v)) for s in seeds for a in GRID_ALPHAS for v in GRID_LAMBDAS]
    if study == "noise":
        return [Task("noise", problem, s, noise=nz, noise_seed=ns) for s in seeds for nz in NOISES for ns in noise_seeds]
    if study == "methods":
        return [Task("methods", problem, s, method=m) for s in seeds for m in METHODS]
    raise InputError(f"study: expected one of {STUDIES}, found {study!r}")


def _quiet_local_cluster(LocalCluster, n_workers: int):
    """A local Dask cluster whose worker processes stop with this one and print nothing.

    The workers are started with SIGINT blocked (the mask is inherited by the cluster's thread and by
    every process it starts), so Ctrl-C to the process group stops this process alone, which then
    closes the cluster: no worker prints a ``KeyboardInterrupt`` traceback. Dask's own warnings
    about tasks cancelled by that close are not shown (``silence_logs``: errors only), and
    multiprocessing's resource tracker is started with its stderr on ``/dev/null`` so that a SIGKILL
    of this process does not make it print a leaked-semaphore warning. Dask workers already die with
    their parent (its nanny watches a pipe to the parent)."""
    import logging
    import signal

    _start_resource_tracker_quietly()
    blocked = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        return LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True, dashboard_address=":0",
                            silence_logs=logging.ERROR)
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, blocked)  # a Ctrl-C held back meanwhile arrives now


def _start_resource_tracker_quietly() -> None:
    try:
        from multiprocessing import resource_tracker

        saved, devnull = os.dup(2), os.open(os.devnull, os.O_WRONLY)
    except (ImportError, OSError):  # pragma: no cover
        return
    try:
        os.dup2(devnull, 2)
        resource_tracker.ensure_running()
    finally:
        os.dup2(saved, 2)
        os.close(saved)
        os.close(devnull)


def run_tasks(tasks, scheduler: str | None = None, workers: int | None = None, progress: bool = True) -> list[dict]:
    """Run tasks on Dask: a local cluster of ``workers`` processes (default: one per core), or the
    scheduler at ``scheduler`` (e.g. ``tcp://10.0.0.5:8786``) for a real cluster. Returns the rows
    in task order. A failing task raises its own exception here, naming the task."""
    from dask.distributed import Client, LocalCluster, as_completed

    tasks = list(tasks)
    if not tasks:
        return []
    if scheduler:
        client = Client(scheduler)
        cluster = None
    else:
        cluster = _quiet_local_cluster(LocalCluster, workers or available_cores())
        client = Client(cluster)
    try:
        futures = client.map(run_task, tasks, pure=False)
        index = {f.key: i for i, f in enumerate(futures)}
        rows: list = [None] * len(tasks)
        bar = None
        if progress:
            from tqdm import tqdm

            bar = tqdm(total=len(tasks), desc="tasks", unit="task")
        for fut in as_completed(futures):
            i = index[fut.key]
            try:
                rows[i] = fut.result()
            except Exception as exc:
                raise RuntimeError(f"task {tasks[i]} failed: {exc}") from exc
            if bar is not None:
                bar.update(1)
        if bar is not None:
            bar.close()
        return rows
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def table_csv(rows) -> str:
    """The results table (dict rows) as CSV text in :data:`COLUMNS` order."""
    from .tables import csv_table, dict_rows

    return csv_table(COLUMNS, dict_rows(rows, COLUMNS))


def write_table(rows, path) -> None:
    """Write the results table as CSV, atomically."""
    from pathlib import Path

    from ..atomic import atomic_write_bytes

    atomic_write_bytes(Path(path), table_csv(rows).encode())


def read_table(path) -> list[dict]:
    """Read a results table; numeric columns become floats (empty stays None)."""
    from pathlib import Path

    path = Path(path)
    try:
        text = path.read_text()
    except OSError as exc:
        raise InputError(f"{path}: expected a results table (CSV), found an unreadable file ({exc})") from exc
    reader = csv.DictReader(io.StringIO(text))
    if reader.fieldnames is None or not {"study", "method", "heldout_error"} <= set(reader.fieldnames):
        raise InputError(f"{path}: expected a results table with columns {COLUMNS}, found {reader.fieldnames}")
    out = []
    for r in reader:
        row = {}
        for k, v in r.items():
            if k in ("study", "problem", "method"):
                row[k] = v
            else:
                row[k] = None if v == "" else float(v)
        out.append(row)
    return out


__all__ = ["STUDIES", "METHODS", "COLUMNS", "Task", "run_task", "study_tasks", "run_tasks", "write_table",
           "read_table", "person_problem"]
