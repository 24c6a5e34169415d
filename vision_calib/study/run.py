"""Running a study: local processes or a Dask cluster, one file per finished run (atomic), resume
of runs already computed with the same spec hash, then the tables and plots."""

from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path

from ..io.atomic import write_json_atomic
from .cells import run_cell
from .spec import RUN_FORMAT, StudySpec, cell_key, load_study, study_cells
from .tables import cell_summary, parameter_spread, parameter_table, summary_text, write_outputs, \
    write_parameter_table

def _run_task(spec, cell, rep):
    return cell, rep, run_cell(spec, cell, rep)


def _execute(spec, todo, workers, scheduler, on_done):
    """Run ``todo`` [(cell, rep)] and call on_done(cell, rep, row) as each finishes (in this process)."""
    if scheduler is not None:
        from distributed import Client, as_completed

        own = not isinstance(scheduler, Client)
        client = Client(scheduler) if own else scheduler
        try:
            futs = [client.submit(_run_task, spec, c, r, pure=False) for c, r in todo]
            try:
                for fut in as_completed(futs):
                    on_done(*fut.result())
            finally:
                client.cancel(futs)
        finally:
            if own:
                client.close()
        return
    if workers <= 1 or len(todo) <= 1:
        for c, r in todo:
            on_done(*_run_task(spec, c, r))
        return
    import multiprocessing as mp
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait

    from ..experiment.image_chain import die_with_parent

    with ProcessPoolExecutor(max_workers=workers, mp_context=mp.get_context("spawn"), initializer=die_with_parent,
                             initargs=(os.getpid(),)) as ex:
        pending = {ex.submit(_run_task, spec, c, r) for c, r in todo}
        try:
            while pending:
                done, pending = wait(pending, return_when=FIRST_COMPLETED)
                for f in done:
                    on_done(*f.result())
        except BaseException:
            for f in pending:
                f.cancel()
            raise


def _load_run(path: Path, spec_hash: str):
    try:
        d = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    if d.get("spec_hash") != spec_hash or d.get("format") != RUN_FORMAT or not isinstance(d.get("row"), dict):
        return None
    return d["row"]


def run_study(spec, out_dir, workers: int | None = None, scheduler=None, progress: bool = False,
              plots: bool = True) -> dict:
    """Run (or resume) a study and write its outputs in ``out_dir`` (see the module docstring).

    spec: StudySpec or path of the study file. workers: local processes (default: CPU count;
    1 = in this process). scheduler: Dask scheduler address (or a ``distributed.Client``): runs
    go to the cluster instead. plots: write the PNG plots. Returns {name, spec_hash, out_dir, n_runs, n_computed, n_reused,
    n_failed, files, summary (per cell: axes + {metric: {mean, std}}), summary_text}.
    """
    spec = spec if isinstance(spec, StudySpec) else load_study(spec)
    out = Path(out_dir)
    runs_dir = out / "runs"
    runs_dir.mkdir(parents=True, exist_ok=True)
    cells = study_cells(spec)
    plan = [(c, r) for c in cells for r in range(spec.repetitions)]
    rows = {}
    todo = []
    for c, r in plan:
        k = cell_key(c, r)
        row = _load_run(runs_dir / f"{k}.json", spec.hash)
        if row is None:
            todo.append((c, r))
        else:
            rows[k] = row
    n_reused = len(rows)
    t0 = time.perf_counter()
    bar = None
    if progress and todo:
        from tqdm import tqdm

        bar = tqdm(total=len(todo), desc=spec.name, unit="run", file=sys.stderr)

    def on_done(c, r, row):
        k = cell_key(c, r)
        write_json_atomic(runs_dir / f"{k}.json", {"format": RUN_FORMAT, "spec_hash": spec.hash, "key": k, "row": row})
        rows[k] = row
        if bar is not None:
            bar.update(1)

    try:
        _execute(spec, todo, workers or os.cpu_count() or 1, scheduler, on_done)
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
    res["summary_text"] = summary_text(spec, res)
    return res


