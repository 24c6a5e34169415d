"""Sensor effect settings (no torch: the main process builds these without importing torch)."""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from ..errors import ConfigError


@dataclass(frozen=True)
class SensorEffects:
    """Sensor/lens effect parameters (recorded in reports via :meth:`to_dict`).

    apply_distortion: resample with the intrinsics' Brown–Conrady coefficients.
    blur_sigma_px: Gaussian defocus std [px] (0 = none). blur_disc_radius_px: disc defocus
    radius [px] (0 = none; exclusive with the Gaussian). exposure: scale of the ideal intensity
    (1 = nominal). gain: digital gain (grey levels per 255/full_well electrons).
    full_well_e: electrons at grey level 255 for exposure = gain = 1 (0 = no photon noise).
    read_noise_grey: read-noise std [grey levels]. black_level_grey: offset [grey levels].
    vignetting: relative intensity loss at the image corner (0 = none, quadratic in radius).
    photon_model: "gaussian" | "poisson". Output is always clipped and rounded to uint8.
    """

    apply_distortion: bool = True
    blur_sigma_px: float = 0.6
    blur_disc_radius_px: float = 0.0
    exposure: float = 1.0
    gain: float = 1.0
    full_well_e: float = 10000.0
    read_noise_grey: float = 1.0
    black_level_grey: float = 0.0
    vignetting: float = 0.0
    photon_model: str = "gaussian"

    def __post_init__(self):
        for name in ("blur_sigma_px", "blur_disc_radius_px", "exposure", "gain", "full_well_e",
                     "read_noise_grey", "black_level_grey", "vignetting"):
            v = getattr(self, name)
            if not np.isfinite(v) or v < 0:
                raise ConfigError(f"SensorEffects.{name} must be finite and >= 0, got {v!r}")
        if self.vignetting >= 1:
            raise ConfigError(f"SensorEffects.vignetting must be < 1, got {self.vignetting}")
        if self.blur_sigma_px > 0 and self.blur_disc_radius_px > 0:
            raise ConfigError("SensorEffects: give either blur_sigma_px or blur_disc_radius_px, not both")
        if self.photon_model not in ("gaussian", "poisson"):
            raise ConfigError(f"SensorEffects.photon_model must be 'gaussian' or 'poisson', got {self.photon_model!r}")

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict, where: str = "sensor") -> "SensorEffects":
        known = set(cls.__dataclass_fields__)
        unknown = set(d) - known
        if unknown:
            raise ConfigError(f"{where}: unknown sensor effect key(s) {sorted(unknown)} (known: {sorted(known)})")
        try:
            return cls(**d)
        except TypeError as exc:
            raise ConfigError(f"{where}: invalid sensor effects ({exc})") from None

    @classmethod
    def ideal(cls) -> "SensorEffects":
        """No distortion, blur, noise or vignetting (only 8-bit quantisation)."""
        return cls(apply_distortion=False, blur_sigma_px=0.0, full_well_e=0.0, read_noise_grey=0.0)
