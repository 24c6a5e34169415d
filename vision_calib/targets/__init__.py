"""targets stage: ChArUco / AprilTag-grid / chessboard / asymmetric-circle-grid definitions (3-D corners, texture, printable export). cv2 only.

Frame and id conventions are written in :mod:`vision_calib.targets.spec`; the kinds are registered in
:mod:`vision_calib.targets.kinds`.
"""

from .printable import export_printable, read_png_phys
from .sheet import PAPERS, Paper, layout, parse_paper
from .spec import KINDS, TargetSpec, load_target, target_from_dict

__all__ = ["KINDS", "PAPERS", "Paper", "TargetSpec", "export_printable", "layout", "load_target", "parse_paper",
           "read_png_phys", "target_from_dict"]
