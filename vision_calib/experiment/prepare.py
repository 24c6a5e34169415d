"""Preparation steps: what the data determine before identification, for the kinds that declare the need.

One step today, for setups with the capability ``rig.base.TiltsFromAxis`` (H4): the camera and target tilts
(paper §4.1), measured from the rotation axis of the nacelle (``identify.camera_axis.estimate_camera_axis``),
then carried by the kind's four tilt parameters (``TiltsFromAxis.with_tilts``). With ``tilt_mode`` "identify"
(default) all four are identified with the other parameters, the axis estimate entering the fit as a prior
N(axis value, axis std^2) (one prior row each, ``IdentificationProblem.prior_rows``; the estimate's x/y
correlation is below 1e-3 on the demo scene, so the prior is diagonal): the IGM refines what it determines (the
camera tilts, through the camera distance), the target tilts (second order in the joints) keep about the axis
value and its std, and the std and the verdict of the fit carry the axis' uncertainty. No rule decides whether
to free them: the prior leaves the degrees of freedom of the adequacy test unchanged. "axis": the paper's step
alone (tilts fixed at the axis value: their uncertainty is then NOT carried, the info says so); "off": nominal
tilts kept. When the rotations contradict a fixed axis (``CameraAxisEstimate.consistency`` against the measured
rotation covariance: p < AXIS_LEVEL and chi2/dof > AXIS_MAX_VARIANCE_RATIO: rotation noise above the
covariance, e.g. one frame per pose, or a nacelle / mount that moves) the tilts are never left at a value the
data reject: they are identified with the axis prior (its std from the axis fit's residual scatter) in either
mode, and the full fit's adequacy test judges the model; the info dict (report's ``prepared`` block) has the
estimates, the axis test, and then a ``warning``.
"""

from __future__ import annotations

import numpy as np

from ..errors import ConfigError, DataError
from ..identify.camera_axis import estimate_camera_axis
from ..rig.base import Measurements, Setup, TiltsFromAxis

#: significance level at which a measured camera/target tilt replaces the nominal one (chi-square, 2 dof)
AXIS_LEVEL = 1e-3
#: an axis estimate whose std is below this [rad] is exact (noise-free rotations): the tilts are fixed at it
EXACT_AXIS_STD_RAD = 1e-9
#: the rotation axis is "not fixed" (tilts not applied) when the axis fit's residuals fail the chi-square test
#: against the measurements' rotation covariance (level AXIS_LEVEL) AND their variance exceeds the predicted by
#: this factor (residual std twice the predicted, as steps.UNEXPLAINED_CHI2_DOF): image rotations carry a
#: systematic part (detector bias) the covariances only partly model
AXIS_MAX_VARIANCE_RATIO = 4.0
#: the values of ``TiltsFromAxis.tilt_mode``
TILT_MODES = ("identify", "axis", "off")


def prepare_setup(setup: Setup, meas: Measurements) -> tuple[Setup, dict]:
    """(the setup to identify with, a JSON-ready record for the report's ``prepared`` block): the preparation
    steps the setup's capabilities ask for (module docstring); (setup, {}) when none."""
    if isinstance(setup, TiltsFromAxis):
        return tilts_from_axis(setup, meas)
    return setup, {}


def _chi2_2(w, c) -> float:
    """w^T c^-1 w for a 2-vector w and its covariance c (2, 2); inf when c is singular (exact data) and w != 0."""
    try:
        return float(w @ np.linalg.solve(c, w))
    except np.linalg.LinAlgError:
        return float("inf") if np.any(w != 0) else 0.0


def tilts_from_axis(setup: TiltsFromAxis, meas: Measurements) -> tuple[Setup, dict]:
    """The camera/target tilt step of the module docstring on measurements ``meas`` (their rotations and rotation
    covariances); ConfigError naming the setup's class for an unknown ``tilt_mode``."""
    mode = setup.tilt_mode
    if mode not in TILT_MODES:
        raise ConfigError(f"{type(setup).__name__}.tilt_mode: expected 'identify', 'axis' or 'off', got {mode!r}")
    if mode == "off":
        return setup, {"applied": False, "reason": "tilt_mode off"}
    R_BC0, R_ME0 = setup.tilt_reference()
    # rotation noise from the residuals of the axis fit, not from the per-pose covariances: the measured
    # rotations carry a systematic part (detector bias) that the covariances miss
    try:
        est = estimate_camera_axis(meas.T_cam_target, R_BC0=R_BC0, R_ME0=R_ME0)
    except DataError as exc:  # e.g. all poses at one theta: the axis is not determined, keep the nominal
        # (not a value the data reject: they cannot measure it; the full fit's adequacy test still judges it)
        return setup, {"applied": False, "reason": str(exc),
                       "warning": f"the camera/target tilts are not measured ({exc}): they stay nominal, their "
                                  "uncertainty not carried; record poses that differ in theta by several degrees"}
    q = [_chi2_2(w, c) for w, c in ((est.tilt_cam_rad, est.cov_tilt_cam),
                                   (est.tilt_target_rad, est.cov_tilt_target))]
    axis_test = est.consistency(meas.cov[:, 3:, 3:])
    fixed = not (axis_test["chi2"] is not None and axis_test["p_value"] < AXIS_LEVEL
                 and axis_test["chi2_dof"] > AXIS_MAX_VARIANCE_RATIO)
    vals = np.concatenate([est.tilt_cam_rad, est.tilt_target_rad])
    axis_std = np.concatenate([est.tilt_cam_std_rad, est.tilt_target_std_rad])
    usable = bool(np.all(np.isfinite(vals)) and np.all(np.isfinite(axis_std)))
    # exact rotations (noise-free synthetic data) give an exact axis: fixed at it, with its zero std
    exact = bool(usable and fixed and np.max(axis_std) < EXACT_AXIS_STD_RAD)
    # a failed axis test never leaves the tilts at a value the data reject (nominal, or the axis value fixed):
    # they are identified in the full fit, the axis estimate (std from the axis fit's own residual scatter)
    # entering as their prior, and the full fit's adequacy test judges the model
    identify = usable and (mode == "identify" or not fixed) and not exact
    out = setup.with_tilts(vals if usable else np.zeros(4), axis_std if identify else None)
    names = tuple(setup.tilt_names)
    sd_c, sd_t = np.sqrt(np.diag(est.cov_tilt_cam)), np.sqrt(np.diag(est.cov_tilt_target))
    info = {"camera_tilt_deg": np.degrees(est.tilt_cam_rad).tolist(), "camera_tilt_std_deg": np.degrees(sd_c).tolist(),
            "target_tilt_deg": np.degrees(est.tilt_target_rad).tolist(),
            "target_tilt_std_deg": np.degrees(sd_t).tolist(), "rms_residual_deg": float(np.degrees(est.rms_residual_rad)),
            "applied": bool(usable), "chi2_camera_target": q,
            "identified": list(names) if identify else [],
            "prior": ({n: {"mean_deg": float(np.degrees(v)), "std_deg": float(np.degrees(s))}
                       for n, v, s in zip(names, vals, axis_std)} if identify else None),
            "axis_fixed": bool(fixed), "axis_test": axis_test,
            "method": "rotation axis of the nacelle (paper 4.1); tilts relative to the nominal, about the camera "
                      "x/y and target x/y axes; "
                      + ("the four tilts are identified with the other parameters, the axis estimate entering "
                         "the fit as a prior (mean and std above, one prior row each): the parameter table's "
                         "tilt std carry it" if identify else
                         "tilts fixed at the axis value (tilt_mode 'axis', the paper's step): their std is not "
                         "carried into the other parameters' std")
                      + "; when the rotations do not share one fixed axis within the noise (axis_test: chi2 of the "
                      f"axis fit's residuals against the rotation covariance, level {AXIS_LEVEL}, chi2/dof > "
                      f"{AXIS_MAX_VARIANCE_RATIO}) the tilts are identified with the axis prior whatever the "
                      "tilt_mode"}
    if not usable:
        info["warning"] = ("the rotation axis estimate is not finite: the camera/target tilts stay nominal, their "
                           "uncertainty not carried (record poses that differ in theta by several degrees)")
    elif not fixed:
        info["warning"] = (
            f"the measured rotations do not share one fixed rotation axis within their predicted noise (axis fit "
            f"chi2/dof {axis_test['chi2_dof']:.3g}, p {axis_test['p_value']:.2g}, rotation residual RMS "
            f"{np.degrees(est.rms_residual_rad):.3g} deg): either the rotation noise is larger than the "
            "measurement's covariance says (few frames per pose) or the nacelle or a mount moves with the pose; "
            "the camera/target tilts are identified in the full fit with the axis estimate as their prior (std "
            "from the axis fit's residual scatter"
            + (", tilt_mode 'axis' overridden: a fixed axis value is rejected by the data" if mode == "axis" else "")
            + "), and the full fit's adequacy test judges whether the model holds")
    elif mode == "axis":
        info["note"] = ("tilt_mode 'axis': camera/target tilts fixed at the rotation-axis estimate (std "
                        f"{', '.join(f'{np.degrees(s):.3g}' for s in axis_std)} deg), not carried into the std")
    return out, info


__all__ = ["AXIS_LEVEL", "AXIS_MAX_VARIANCE_RATIO", "EXACT_AXIS_STD_RAD", "TILT_MODES", "prepare_setup",
           "tilts_from_axis"]
