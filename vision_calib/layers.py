"""The package's architecture contract: its floors, top first (checked by ``tests/test_architecture.py``).

A module may import modules of its own package (subpackage) and of any floor *below* its own; never a floor
above, never a sibling on its own floor (siblings are independent). Inside a package and across packages
the module-level import graph (lazy imports inside functions included) has no circle; no module imports
another module's private (``_underscore``) names; ``identify`` and ``kinematics``, and everything they
import, import no cv2, torch, kornia, pyrender or OpenGL.

Names are the top-level modules and subpackages of :mod:`vision_calib`.
"""

LAYERS: tuple[tuple[str, ...], ...] = (
    ("cli",),
    ("study",),
    ("sim",),
    ("planning",),
    ("experiment",),
    ("report",),  # what a run says about itself (report.json, summary, HTML, plots): written by experiment
    ("deploy",),  # a result to the robot (CalibratedRobot) and to its controller's files (deploy.export)
    ("io",),  # data files only, read and written
    ("measure",),
    ("rig",),
    ("identify", "render", "sensor"),
    ("kinematics", "targets", "camera"),
    ("config",),
    ("frames",),
    ("errors", "serialize", "plugins", "layers", "shipped"),
)

#: third-party modules that ``identify`` and ``kinematics`` (and what they import) must not import
HEAVY = ("cv2", "torch", "kornia", "pyrender", "OpenGL", "trimesh")
LIGHT = ("identify", "kinematics")

#: known exceptions to the contract, each with its reason (module, imported module): the test fails when one
#: is no longer needed, so the list only shrinks
EXCEPTIONS: dict[tuple[str, str], str] = {}
