"""study: a parameter sweep x Monte Carlo repetitions of one scene, run locally (processes) or
on a Dask cluster, resumable, written as a tidy table + summary + plots (``vision-calib study``).

Spec file (YAML; paths relative to the spec file)::

    name: h4_pose_count              # default: the file's stem
    scene: ../h4_vision.yaml         # required
    mode: synthetic                  # synthetic (pose measurements + Gaussian noise, experiment.synthetic)
                                     # | images (render + measure, experiment.simulate)
    repetitions: 100                 # Monte Carlo runs per sweep point (> 0)
    seed: 0                          # study seed (int)
    description: free text           # optional, ignored
    truth: scene                     # scene: one true robot (the scene's truth.seed) for every run
                                     # | per_run: a new random truth per repetition (seeded by the run seed)
    truth_variant: H                 # optional, H4 + synthetic: measurements come from this variant's
                                     # robot (e.g. model 31 with deviations on all its free parameters)
                                     # while each cell identifies its own variant/model (model error);
                                     # accuracy and V1..V3 are evaluated across models, err: columns
                                     # only for parameter names both models share
    settings: {n_poses: 71}          # optional constants applied to every run (same keys as sweep)
    sweep:                           # cartesian product of the axes (may be empty: one cell)
      n_poses: [6, 15, 71]
      "sigma_mm,sigma_deg": [[0.05, 0.0075], [0.1, 0.015]]   # linked axes: varied together
    outputs: [parameters, accuracy, criteria, condition]      # default: all four
    parameters: [h4.L, h4.l]         # optional: parameters recorded in the table (default: all)
    target: {position_rms_mm: 0.1}   # optional: accuracy targets after calibration (position_rms_mm,
                                     # position_max_mm, rotation_rms_deg, V2_rad, V3_m) -> budget.csv
    max_hours: 20                    # optional: the wall time [h] this study may take; a study estimated
                                     # longer (or beyond the machine's memory / free disk) stops before
                                     # any run unless --yes (study/budget.py; default bound 1 h)

Sweep/settings keys: ``n_poses`` (int > 0: subset drawn at random from the scene's poses),
``sigma_mm``, ``sigma_deg`` (pose noise per component, >= 0), ``method`` (lse|ekf|igm; igm = H4
only), ``residual`` (pose|position for serial scenes, joint for H4), ``variant`` (H4 paper table 2,
A..H: the scene's robot is replaced by ``kinematics.h4_variants.variant(robot, letter)`` of the model-12 robot, E..H
are model 31, the free mask follows), ``model`` ("12"|"31", H4), ``trial`` (serial scenes whose
robot file has ``trials``, e.g. the thesis' chapter 3-4 experiments: the truth is the trial's
deviation vector, and when the scene's poses are ``kind: configurations`` they become the trial's
own configuration set), ``pose_selection`` (mode synthetic: ``random`` = the default, a random
subset of ``n_poses`` drawn per repetition; ``D`` | ``E`` = the ``n_poses`` poses of the scene's
pose pool -- the whole grid81 / configuration set, or for ``kind: random`` the scene's ``count``
poses drawn with repetition 0's pose stream -- that maximise log det (D-optimal, Borm-Menq O1) or
the smallest singular value (E, O3) of the scaled whitened identification Jacobian of the
identifiable parameters, ``identify.pose_selection.select_poses``; computed at the nominal
geometry with exact measurements weighted by the cell's noise sigmas, so it never sees the truth
or the noise draws: the subset is the same in every repetition, the noise still varies), and for
mode images only
``noise_grey``, ``blur_px`` (sensor effects) and ``frames`` (frames per pose).

Reproducibility. A run = (cell, repetition) is a pure function of the spec, the cell's values and
the run seed ``seed = SeedSequence([spec.seed, repetition]).generate_state(1)[0]`` (uint32). The
run seed does not depend on the sweep values: every cell of repetition r uses the same pose/noise
streams (``synthetic.rngs``), i.e. common random numbers -- the noise draws of a repetition are
shared across sweep values, and with ``n_poses`` the subsets come from the same generator state
(not nested, since ``rng.choice`` of another size draws differently). Results do not depend on the
number of workers or on the executor (local processes or Dask).

Outputs (in ``out_dir``):

- ``runs/<cell-key>.json``: one file per finished run (written atomically as it completes), with
  the spec hash; on start, runs whose file exists with the same hash are reused, not recomputed.
  The hash covers the scene/robot/target files and every spec entry except ``name``, ``sweep``
  and ``repetitions`` (which only select which runs exist: adding repetitions or sweep values
  reuses what was computed). It does not cover the package's code: delete ``runs/`` after a
  code change that alters the numbers.
- ``results.csv`` / ``results.parquet``: tidy table, one row per run: ``study``, the sweep axes,
  ``repetition``, ``seed``, ``error`` (message of a run that failed with a VisionCalibError, else
  empty), ``converged``, ``iterations``, ``seconds`` (identification time), ``n_free``; with
  ``accuracy``: ``before_``/``after_`` ``position_rms_mm``, ``position_max_mm``,
  ``rotation_rms_deg`` (validation poses; before = nominal, after = identified parameters); with
  ``criteria`` (H4): ``before_``/``after_`` ``V1_rad``, ``V2_rad``, ``V3_m``; with
  ``condition``: ``cond`` (condition number of the scaled, whitened identification Jacobian of the
  identifiable parameters at the nominal over the run's poses, ``identify.analyze``); with
  ``parameters``: wide columns ``err:<name>`` (identified - true, SI: m or rad) and
  ``std:<name>`` (predicted std, SI) for every parameter (NaN where fixed / not in the model).
- ``parameters.csv`` (mode synthetic, ``truth: scene``, with ``parameters``): one row per (cell,
  parameter) for the free parameters and those with a true deviation: ``true_deviation``
  (x_true - nominal, SI), ``identifiable`` (yes/no: in the cell's base set), ``noise_free``
  (deviation identified from exact measurements on the poses of repetition 0: what the
  identifiable parameters converge to when the truth has non-identifiable parts, e.g. d2 absorbs
  d3), ``identified_mean``, ``mc_std`` (Monte Carlo std), ``predicted_std`` (mean), ``mc_rms_error``
  (RMS of identified - true), ``note`` (coupling of a non-identifiable parameter, or why it is
  fixed) and ``thesis_reported`` (the robot file's ``reported`` estimate of a ``trial`` truth).
  The summary text prints it when the sweep has ``trial`` or the study has at most 2 cells.
- ``summary.csv``: long table, one row per (cell, metric): the axes, ``metric``, ``n`` (finite
  values), ``mean``, ``std`` (ddof 1), ``rms``, ``p05``, ``p50``, ``p95``. For ``err:`` metrics
  with ``truth: scene`` the std is the Monte Carlo std of the identified parameter.
- ``budget.csv`` (with ``target``): see Budget below.
- plots (PNG): ``<metric>_vs_<axis>.png`` (median and 5-95 % band of the main figures vs each
  swept axis) and ``param_std_vs_<axis>.png`` (Monte Carlo std of each identified parameter).

Execution. A run is computed where it is scheduled: in this process (``workers`` 1), in one of ``workers``
spawned local processes, or on a Dask worker (threads or processes, daemonic or not). An images-mode run renders
and measures in that process's thread itself (``image_chain.InlineImagePool``: the study's workers are its
parallelism, so no run starts a pool of its own -- a daemonic Dask worker may not have children), with what only
the setup determines (target geometry, renderer, sensor tables, detector objects) built once per worker thread and
reused by its next runs, and without ``simulate``'s synthetic reference (5 more identifications the row does not
record). Local workers die with the main process (also after kill -9); on an error or Ctrl-C in the main process
they are stopped at once, and the finished runs are kept in ``runs/`` for a resume.

Budget (``target`` given): ``budget.csv`` and summary lines (:mod:`.budget`): per sensor condition (the values of
the axes other than ``frames`` and ``n_poses``) and target figure, the cheapest cell -- fewest images = poses x
frames per pose, then fewest poses -- whose 95th percentile of the after-calibration figure meets the target
(failed runs count as missing it), else "not reached" with the best cell. Not part of the spec hash: a new target
reuses every run. The plots draw it as a dashed line.

Workers must see the same files (scene, robot, target) at the same paths: a shared filesystem or
the same checkout on every Dask worker. Only the calling process writes files.

Modules: :mod:`.spec` (the file, validated), :mod:`.cells` (the scene and one run of a cell),
:mod:`.run` (execution, resume), :mod:`.tables` (results/summary/parameter tables, summary text),
:mod:`.budget` (the target's budget table), :mod:`.plots`.
"""

from .cells import run_cell
from .run import run_study
from .spec import StudySpec, cell_key, load_study, run_seed, scene_with, scene_with_trial, study_cells
from .tables import cell_summary, parameter_table, summary_rows

__all__ = ["StudySpec", "load_study", "run_study", "run_cell", "study_cells", "run_seed", "cell_key", "scene_with",
           "scene_with_trial", "summary_rows", "cell_summary", "parameter_table"]
