"""Toy target kind shipped by a plugin package: rows x cols isolated black squares of side_m, one square apart."""

from dataclasses import dataclass

import numpy as np

from vision_calib.targets.kinds import TargetKind, TargetSpec


@dataclass(frozen=True)
class SquaresSpec(TargetSpec):
    side_m: float = 0.0


class SquaresKind(TargetKind):
    name = "plugin_squares"
    spec_class = SquaresSpec
    required = ("side_m",)

    def validate(self, spec, where):
        self.positive(spec, where, "side_m")

    def pattern_size_m(self, spec):
        return (2 * spec.cols - 1) * spec.side_m, (2 * spec.rows - 1) * spec.side_m

    def corner_points(self, spec):
        r, c = np.divmod(np.arange(spec.rows * spec.cols), spec.cols)
        p = np.column_stack([2 * c * spec.side_m, 2 * r * spec.side_m, np.zeros(r.size)])
        return np.arange(len(p)), p

    def black_rects(self, spec):
        _, p = self.corner_points(spec)
        return [(x, y, x + spec.side_m, y + spec.side_m) for x, y, _ in p]
