"""vision_calib: vision-based geometric calibration of robots.

Pipeline stages (one subpackage each): kinematics -> targets/render/sensor -> measure -> identify ->
experiment, which writes its report (``report``); ``io`` reads and writes the data files, ``deploy`` takes a
result to the robot and its controller; ``cli`` is a thin wrapper. The floors: ``vision_calib.layers``; the
documentation: ``vision-calib docs``. Conventions: ``T_a_b`` is the 4x4 pose of frame b in frame a, SI units
inside.
"""

__version__ = "0.1.0"
