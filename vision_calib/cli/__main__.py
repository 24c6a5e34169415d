"""``python -m vision_calib.cli ...``: the ``vision-calib`` command."""

from . import run

run()
