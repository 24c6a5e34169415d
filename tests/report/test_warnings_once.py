"""A warning given by two steps (the experiment and the identification) is counted and shown once."""

from types import SimpleNamespace

import numpy as np

from vision_calib.report.build import verdict
from vision_calib.report.summary import summary_text


def _result(warnings):
    return SimpleNamespace(converged=True, identified=np.zeros(2), std=np.ones(2), free=np.ones(2, bool),
                           cost_final=1.0, warnings=list(warnings), message="")


def test_a_warning_in_both_lists_counts_once():
    w = "3 poses rejected as outliers: 001, 002, 003"
    assert verdict(_result([w]), warnings=[w, w])["warnings"] == 1
    assert verdict(_result([w]), warnings=["other"])["warnings"] == 2
    assert verdict(_result([]), warnings=[])["warnings"] == 0


def test_summary_prints_a_shared_warning_once():
    w = "3 poses rejected as outliers: 001, 002, 003"
    report = {"verdict": verdict(_result([w]), warnings=[w]), "kind": "process", "source": {}, "settings": {},
              "warnings": [w], "identification": {"method": "lse", "converged": True, "iterations": 3,
                                                   "cost_initial": 10.0, "cost_final": 1.0, "warnings": [w]}}
    assert summary_text(report).count(w) == 1
