"""cpc2urdf: calibrate active robot heads and turn the result into a URDF you can trust.

Conventions (see DESIGN.md): SI units inside (m, rad); ``T_a_b`` is the pose of frame b in frame
a (maps b-coordinates to a-coordinates, Pinocchio's ``aMb``); points carry their frame
(``p_world``); camera optical frames follow REP-103 (z forward, x right, y down).

Sub-packages: ``cpc2urdf.identification`` (measurements to parameters), ``cpc2urdf.validation``
(URDF cross-checks, accuracy, gaze, viewing), ``cpc2urdf.robots`` (shipped robot specs).
"""

from cpc2urdf.errors import Cpc2UrdfError
from cpc2urdf.model import CPCModel, CPCParams, Frame, Joint, RobotStructure
from cpc2urdf.model_file import save_model
from cpc2urdf.robot_ref import load_model, load_robot

__version__ = "0.1.0"

__all__ = [
    "CPCModel",
    "CPCParams",
    "Cpc2UrdfError",
    "Frame",
    "Joint",
    "RobotStructure",
    "__version__",
    "load_model",
    "load_robot",
    "save_model",
]
