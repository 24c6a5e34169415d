"""rig: what is calibrated. One :class:`Setup` protocol per robot kind (parameters, measurement
model, Jacobian via the identification problem, ``evaluate``), the kinds registered in ONE place
(:mod:`.registry`), and scenes loaded once into typed settings in SI units (:mod:`.scene`)."""

from .base import Evaluation, Measurements, Setup, pose_cov_from_sigmas, pose_noise
from .registry import KINDS, get_kind, register, unregister
from .scene import SCENES_DIR, Scene, load_scene, scene_poses, true_parameters

__all__ = ["Evaluation", "Measurements", "Setup", "pose_cov_from_sigmas", "pose_noise", "KINDS", "get_kind", "register",
           "unregister", "SCENES_DIR", "Scene", "load_scene", "scene_poses", "true_parameters"]
