"""deploy stage: from a calibration result to the controller.

:class:`CalibratedRobot` (``CalibratedRobot.load(result_folder_or_calibrated_model_yaml, tcp=None)``): forward
kinematics with its covariance, inverse kinematics on the calibrated model (the branch nearest given joints),
compensation of joint commands meant for the nominal model (row by row: :class:`Compensation`, damped near a
singularity), the joint offsets a controller can take. The file exports a controller reads (URDF, DH
table, UR kinematics YAML, ROS static transforms) are in :mod:`vision_calib.deploy.export`.
"""

from .kinematics import PoseNotReachedError
from .robot import CalibratedRobot, Compensation, model_path

__all__ = ["CalibratedRobot", "Compensation", "PoseNotReachedError", "model_path"]
