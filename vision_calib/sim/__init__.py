"""Simulation and benchmark helpers above the pipeline (used by tests and ``benchmarks/``, not by the CLI):
the measurement chain's accuracy on rendered data (:mod:`.accuracy`), simulated calibration views for the
intrinsics (:mod:`.intrinsics_views`), render speed and accuracy figures (:mod:`.render_bench`,
``python -m vision_calib.sim.render_bench``). They pull in render, sensor, rig and experiment, so they sit
above experiment (vision_calib/layers.py)."""
