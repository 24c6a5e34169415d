"""Helpers of the deploy tests: the shipped scenes, one synthetic calibration written as a result folder, workspace
joint sets (``vision_calib.sim.deploy_truth``: the benchmark uses the same)."""

from vision_calib.sim.deploy_truth import calibrate_scene as calibrate  # noqa: F401
from vision_calib.sim.deploy_truth import workspace_joints  # noqa: F401

SCENES = ("rx90_eye_in_hand", "ur5e_eye_in_hand", "h4_vision")
