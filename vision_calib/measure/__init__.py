"""measure stage: corner detection, undistortion, planar PnP, frame averaging, pose covariance."""

from .batch import detect_batch
from .detect import DetectConfig, Detection, detect, load_gray
from .pnp import (crlb_pose_cov, pose_cov_from_jacobian, project_pinhole, reprojection_jacobian,
                  solve_pnp_planar, undistort_px)
from .handeye import hand_eye_consistency
from .pose import MeasureConfig, PoseMeasurement, measure_images, measure_pose

__all__ = [
    "DetectConfig", "Detection", "detect", "detect_batch", "load_gray",
    "crlb_pose_cov", "pose_cov_from_jacobian", "project_pinhole", "reprojection_jacobian",
    "solve_pnp_planar", "undistort_px",
    "hand_eye_consistency", "MeasureConfig", "PoseMeasurement", "measure_images", "measure_pose",
]
