"""vision_calib: vision-based geometric calibration of robots.

Pipeline stages (one subpackage each): kinematics -> targets/render/sensor -> measure ->
identify -> experiment -> io; ``cli`` is a thin wrapper. See DESIGN.md conventions:
``T_a_b`` is the 4x4 pose of frame b in frame a, SI units inside.
"""

__version__ = "0.1.0"
