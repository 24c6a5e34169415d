"""sensor stage: lens distortion, blur, exposure and noise on batches of frames (torch + kornia)."""

from .effects import SensorEffects, apply_effects, deterministic_image, distortion_source_map

__all__ = ["SensorEffects", "apply_effects", "deterministic_image", "distortion_source_map"]
