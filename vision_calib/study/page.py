"""index.html of a study's output folder: one self-contained page (no network, images inlined, no script) with
the per-cell summary table, the parameter spread, the budget, the failed runs and every plot of the study; the
page helpers are report.html's (``vision_calib.report.html``)."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

from ..serialize import write_text_atomic
from ..report.html import esc, num, page, png_img, table
from .budget import budget_text
from .spec import StudySpec, format_value
from .tables import summary_table

#: the file name in the study's output folder
INDEX_NAME = "index.html"


def study_html(spec: StudySpec, res: dict, table_rows: list[dict], out_dir) -> str:
    """The page of a study result ``res`` (``run.run_study``'s dict, its ``summary_text`` included), the run
    rows ``table_rows`` (their ``error`` keys: the failed runs) and the plots listed in ``res["files"]["plots"]``
    (paths, read from ``out_dir`` by name)."""
    head, body = summary_table(spec, res)
    n_axes = len(spec.axes)
    parts = [f"<h1>Study {esc(spec.name)}</h1>",
             f'<p class="sub">{res["n_runs"]} runs ({res["n_computed"]} computed, {res["n_reused"]} reused, '
             f'{res["n_failed"]} failed); swept: {esc(", ".join(spec.axes) or "nothing")}; '
             f'{spec.repetitions} repetitions per cell; seed {esc(spec.seed)}</p>',
             '<section id="summary"><h2>Summary per cell</h2><p class="muted">mean ± std over the runs of each '
             "cell, after calibration (runs: those that did not fail; conv: fraction converged; cond: condition "
             "number, mean)</p>",
             table(head, [[esc(c) for c in row] for row in body], left=tuple(range(n_axes))), "</section>"]
    spread = res.get("parameter_spread") or []
    if spread:
        rows = [[*(esc(format_value(o[a])) for a in spec.axes), num(o["predicted_std_geomean"], ".3g"),
                 num(o["mc_rms_error_geomean"], ".3g"), esc(o["n_params"]), num(o["predicted_std_vs_first"], ".3g")]
                for o in spread]
        parts += ['<section id="spread"><h2>Parameter spread</h2><p class="muted">geometric mean over the identified '
                  "parameters, SI units; the predicted std should match the Monte Carlo RMS error</p>",
                  table([*spec.axes, "predicted std", "Monte Carlo RMS error", "parameters", "predicted std / first cell"],
                        rows, left=tuple(range(n_axes))), "</section>"]
    if res.get("budget"):
        parts.append('<section id="budget"><h2>Budget</h2><pre>' + esc("\n".join(budget_text(spec, res["budget"])))
                     + "</pre></section>")
    errors = Counter(str(r["error"]) for r in table_rows if r.get("error"))
    if errors:
        parts.append('<section id="failed"><h2>Failed runs</h2>' + table(
            ["runs", "error"], [[esc(n), esc(e)] for e, n in errors.most_common()], left=(1,)) + "</section>")
    figs = []
    for p in (res.get("files") or {}).get("plots") or []:
        name = Path(p).name
        img = png_img(Path(out_dir) / name, name)
        if img:
            figs.append(f"<figure>{img}<figcaption>{esc(name)}</figcaption></figure>")
    parts.append('<section id="plots"><h2>Plots</h2>' + ('<div class="grid">' + "\n".join(figs) + "</div>" if figs
                                                          else "<p>no plots (--no-plots, or no run succeeded)</p>")
                 + "</section>")
    names = sorted({Path(str(v)).name for k, v in (res.get("files") or {}).items() if k != "plots" and v})
    parts.append('<section id="more"><h2>Files and the text summary</h2><p>files beside this page: '
                 + ", ".join(f'<a href="{esc(n)}">{esc(n)}</a>' for n in names) + "</p><details><summary>"
                 "summary text</summary><pre>" + esc(res.get("summary_text", "").replace(f"-> {res.get('out_dir')}", "-> .")) +
                 "</pre></details></section>")  # no absolute path in the page: it moves with its folder
    return page(f"vision_calib study {spec.name}", "\n".join(parts))


def write_index(spec: StudySpec, res: dict, table_rows: list[dict], out_dir) -> Path:
    """Write ``out_dir/index.html`` (atomic) and return its path."""
    return write_text_atomic(Path(out_dir) / INDEX_NAME, study_html(spec, res, table_rows, out_dir))
