"""Running a study: local processes or a Dask cluster, one file per finished run (atomic), resume
of runs already computed with the same spec hash, then the tables, the plots and the study page (index.html)."""

from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path

from ..serialize import write_json_atomic
from .budget import budget_table, budget_text, check_study, write_budget
from .page import write_index
from .cells import run_cell
from .spec import RUN_FORMAT, StudySpec, cell_key, load_study, study_cells
from .tables import cell_summary, parameter_spread, parameter_table, summary_text, write_outputs, \
    write_parameter_table

def _run_task(spec, cell, rep, in_worker: bool = False):
    """One run -> (cell, rep, row). in_worker: this process is a study worker (local or Dask) whose parallelism is
    the study's: one OpenCV/Mesa thread, image buffers from the heap (``image_chain.study_worker_settings``, also
    undoing a Dask nanny's malloc setting that doubles an images run's CPU; idempotent)."""
    if in_worker:
        from ..experiment.image_chain import study_worker_settings

        study_worker_settings()
    return cell, rep, run_cell(spec, cell, rep)


def _local_worker_init(main_pid: int) -> None:
    """Initialiser of a local study worker: dies with the main process (also after kill -9), ignores Ctrl-C (the
    terminal sends SIGINT to the whole process group: the main process alone decides, and stops the workers)."""
    import signal

    from ..experiment.image_chain import die_with_parent, study_worker_settings

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    die_with_parent(main_pid)
    study_worker_settings()


#: seconds a study waits to connect to a Dask scheduler, then for its first worker, before it stops with an error
#: naming the scheduler (a scheduler with no worker would otherwise keep the study at 0/N without a word)
CONNECT_TIMEOUT_S = 10.0
WORKER_WAIT_S = 10.0


def scheduler_address(text: str) -> tuple[str, str | None]:
    """(address, the scheduler file it was read from or None) of ``--scheduler``: an address ``tcp://host:port``
    (tls://, ...) as given, or a scheduler file as ``dask scheduler --scheduler-file FILE`` writes it (JSON with an
    ``address``). ConfigError naming the file when it is not one."""
    from ..errors import ConfigError

    if "://" in text:
        return text, None
    path = Path(text)
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        raise ConfigError(f"{path}: not a Dask scheduler file (JSON with an 'address', written by `dask scheduler "
                          f"--scheduler-file {path}`): {exc}") from None
    addr = doc.get("address") if isinstance(doc, dict) else None
    if not isinstance(addr, str) or "://" not in addr:
        raise ConfigError(f"{path}: not a Dask scheduler file (JSON with an 'address', written by `dask scheduler "
                          f"--scheduler-file {path}`): no 'address' tcp://host:port in it")
    return addr, str(path)


def _connect(distributed, scheduler):
    """(client, whether we own it, the scheduler's name for messages): a connection to ``scheduler`` (an address,
    a scheduler file or a Client) with at least one worker; ConfigError naming the scheduler (and its file) when it
    cannot be reached within CONNECT_TIMEOUT_S, or has no worker after WORKER_WAIT_S."""
    from ..errors import ConfigError

    if isinstance(scheduler, distributed.Client):
        client, own, name = scheduler, False, "the Dask scheduler"
    else:
        addr, file = scheduler_address(str(scheduler))
        name = f"Dask scheduler {addr}" + (f" (from {file})" if file else "")
        try:
            client = distributed.Client(addr, timeout=CONNECT_TIMEOUT_S)
        except (OSError, TimeoutError, ValueError) as exc:
            raise ConfigError(f"{name}: cannot connect within {CONNECT_TIMEOUT_S:g} s ({str(exc).splitlines()[0]}): "
                              "is the scheduler running and reachable from here?") from None
        own = True
    try:
        client.wait_for_workers(1, timeout=WORKER_WAIT_S)
    except TimeoutError:  # (distributed's WorkerStartTimeoutError is one)
        addr = getattr(client.scheduler, "address", None) or "SCHEDULER"
        if own:
            client.close()
        raise ConfigError(f"{name}: no worker connected within {WORKER_WAIT_S:g} s: start workers (`dask worker "
                          f"{addr}`), then run the study again (finished runs are kept)") from None
    return client, own, name


def _execute_dask(spec, todo, scheduler, on_done, check=None):
    """``todo`` on the Dask cluster; ``check(n_threads)``: called once connected with the cluster's total thread
    count (the study's resource check)."""
    from ..errors import import_extra

    distributed = import_extra("distributed", "cluster", "a study on a Dask cluster (--scheduler)")
    as_completed = distributed.as_completed

    client, own, _ = _connect(distributed, scheduler)
    try:
        if check is not None:
            check(sum(client.nthreads().values()) or 1)
        futs = [client.submit(_run_task, spec, c, r, True, pure=False) for c, r in todo]
        try:
            for fut in as_completed(futs):
                on_done(*fut.result())
        finally:
            client.cancel(futs)
    finally:
        if own:
            client.close()


def _execute_local(spec, todo, workers, on_done):
    """``todo`` on ``workers`` spawned processes (each runs its runs' image chain itself, no pool of its own).
    On an error or Ctrl-C in this process the workers are stopped at once (SIGTERM), not waited for."""
    import multiprocessing as mp
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait

    before = set(mp.active_children())
    ex = ProcessPoolExecutor(max_workers=min(workers, len(todo)), mp_context=mp.get_context("spawn"),
                             initializer=_local_worker_init, initargs=(os.getpid(),))
    ok = False
    try:
        pending = {ex.submit(_run_task, spec, c, r, True) for c, r in todo}
        while pending:
            done, pending = wait(pending, return_when=FIRST_COMPLETED)
            for f in done:
                on_done(*f.result())
        ok = True
    finally:
        ours = set(mp.active_children()) - before
        if not ok:  # error (of a run, of on_done) or KeyboardInterrupt: stop the running runs too
            for p in ours:
                p.terminate()
        ex.shutdown(wait=True, cancel_futures=True)  # after a normal end the workers exit when the queue closes
        for p in ours:
            p.join(10)
            if p.is_alive():  # pragma: no cover (SIGTERM not honoured)
                p.kill()
                p.join()


def _execute(spec, todo, workers, scheduler, on_done, check=None):
    """Run ``todo`` [(cell, rep)] and call on_done(cell, rep, row) as each finishes (in this process): on the Dask
    cluster ``scheduler``, on ``workers`` local processes, or here (``workers`` 1). In every case an images-mode
    run renders and measures in the process (thread) that runs it, never in a pool of its own. ``check(workers)``:
    the resource check, called before the first run with the number of workers that will run them."""
    if scheduler is not None:
        _execute_dask(spec, todo, scheduler, on_done, check)
        return
    if check is not None:
        check(min(workers, max(len(todo), 1)))
    if workers <= 1 or len(todo) <= 1:
        for c, r in todo:
            on_done(*_run_task(spec, c, r))
    else:
        _execute_local(spec, todo, workers, on_done)


def _load_run(path: Path, spec_hash: str):
    try:
        d = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    if d.get("spec_hash") != spec_hash or d.get("format") != RUN_FORMAT or not isinstance(d.get("row"), dict):
        return None
    return d["row"]


def run_study(spec, out_dir, workers: int | None = None, scheduler=None, progress: bool = False,
              plots: bool = True, yes: bool = False) -> dict:
    """Run (or resume) a study and write its outputs in ``out_dir`` (see the module docstring).

    spec: StudySpec or path of the study file. workers: local processes (default: CPU count;
    1 = in this process). scheduler: Dask scheduler address, scheduler file (:func:`scheduler_address`) or a
    ``distributed.Client``: runs go to the cluster instead (ConfigError naming it when it cannot be reached or has
    no worker within seconds). plots: write the PNG plots. yes: run even when the estimated time, memory or run
    files exceed the machine or the spec's ``max_hours`` (``budget.check_study``; otherwise ConfigError with the
    estimate, before any run). Returns {name, spec_hash, out_dir, n_runs, n_computed, n_reused,
    n_failed, files, summary (per cell: axes + {metric: {mean, std}}), summary_text}.
    """
    spec = spec if isinstance(spec, StudySpec) else load_study(spec)
    out = Path(out_dir)
    runs_dir = out / "runs"
    cells = study_cells(spec)
    plan = [(c, r) for c in cells for r in range(spec.repetitions)]
    rows = {}
    todo = []
    existing = {p.name for p in runs_dir.iterdir()} if runs_dir.is_dir() else set()  # one listing, not an open() per run
    for c, r in plan:
        k = cell_key(c, r)
        row = _load_run(runs_dir / f"{k}.json", spec.hash) if f"{k}.json" in existing else None
        if row is None:
            todo.append((c, r))
        else:
            rows[k] = row
    n_reused = len(rows)
    t0 = time.perf_counter()
    bar = None

    def on_done(c, r, row):
        k = cell_key(c, r)
        write_json_atomic(runs_dir / f"{k}.json", {"format": RUN_FORMAT, "spec_hash": spec.hash, "key": k, "row": row})
        rows[k] = row
        if bar is not None:
            bar.update(1)

    def check(n_workers):  # before the first run: the estimate against the machine, then the progress bar
        nonlocal bar
        if todo:
            check_study(spec, len(todo), n_workers, out, yes, " of the Dask cluster" if scheduler is not None else "",
                        n_rows=len(plan))
        runs_dir.mkdir(parents=True, exist_ok=True)
        if progress and todo:
            from tqdm import tqdm

            bar = tqdm(total=len(todo), desc=spec.name, unit="run", file=sys.stderr)

    try:
        _execute(spec, todo, workers or os.cpu_count() or 1, scheduler, on_done, check)
    finally:
        if bar is not None:
            bar.close()
    wall = time.perf_counter() - t0
    table = [rows[cell_key(c, r)] for c, r in plan]
    files = write_outputs(spec, table, out, plots=plots)
    summary = cell_summary(spec, table)
    res = {"name": spec.name, "spec": str(spec.path), "spec_hash": spec.hash, "out_dir": str(out),
           "n_runs": len(plan), "n_computed": len(todo), "n_reused": n_reused,
           "n_failed": sum(1 for row in table if row.get("error")), "wall_seconds": wall, "files": files,
           "summary": summary}
    res["parameter_spread"] = parameter_spread(spec, table)
    res["parameters"] = parameter_table(spec, table)
    if res["parameters"]:
        files["parameters_csv"] = write_parameter_table(spec, res["parameters"], out)
    res["budget"] = budget_table(spec, table)
    if res["budget"]:
        files["budget_csv"] = write_budget(spec, res["budget"], out)
    res["summary_text"] = "\n".join([summary_text(spec, res), *budget_text(spec, res["budget"])])
    files["index_html"] = str(write_index(spec, res, table, out))  # the study page: table and plots (study/page.py)
    return res


