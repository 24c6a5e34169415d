"""Exception hierarchy. Every error a user can cause derives from :class:`VisionCalibError`;
the CLI turns these into a one-line message and a non-zero exit code (never a traceback)."""


class VisionCalibError(Exception):
    """Base class of all errors raised on bad input or impossible requests."""

    exit_code = 2


class ConfigError(VisionCalibError):
    """Invalid scene/target/study/recording file: message names the file, the key and what was expected."""


class DataError(VisionCalibError):
    """Bad data: NaN values, missing or mismatched files, unreadable images, too few usable poses."""


class ParameterError(VisionCalibError):
    """Unknown parameter name or an invalid fix/free request."""


class UnreachablePoseError(VisionCalibError):
    """A pose cannot be reached by the (H4) inverse model: message names the pose and the chain."""

    def __init__(self, message: str, pose_index: int | None = None, chain: int | None = None):
        super().__init__(message)
        self.pose_index = pose_index
        self.chain = chain


class IdentifiabilityError(VisionCalibError):
    """The requested parameter set cannot be identified from the given poses (e.g. fewer
    equations than identifiable parameters); message names the parameters."""


class UnknownTopicError(VisionCalibError):
    """``vision-calib docs TOPIC`` with a topic that is not one of the documentation pages: the message lists them."""


class MeasurementError(VisionCalibError):
    """Detection / PnP failed for a whole batch where a per-pose rejection is not possible."""


class MissingExtraError(VisionCalibError, ImportError):
    """An optional dependency is not installed: message names the feature and the extra that installs it
    (e.g. ``pip install 'vision_calib[gpu]'`` for the torch/kornia sensor path)."""


def import_extra(module: str, extra: str, feature: str):
    """``import module`` for ``feature`` (words: what the user asked for), else :class:`MissingExtraError`
    saying which extra of the package installs it and the pip command. Extras: pyproject.toml."""
    import importlib

    try:
        return importlib.import_module(module)
    except ImportError as exc:
        raise MissingExtraError(
            f"{feature} needs {module.split('.')[0]}, which is not installed ({exc}): install the optional extra "
            f"with `pip install 'vision_calib[{extra}]'` (or 'vision_calib[all]' for every extra)") from exc
