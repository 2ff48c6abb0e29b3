"""Named tolerances, defined once, with units. Tests import them from here."""

FK_AGREEMENT_TOL = 1e-9  # [m] and [rad]: CPC model vs a URDF parser, same configuration
UNIT_VECTOR_TOL = 1e-6  # [-]: |b| may differ from 1 by this much in a file before we refuse it
ROTATION_TOL = 1e-6  # [-]: max |R^T R - I| entry accepted for a rotation matrix read from a file
COLLINEAR_TOL = 1e-6  # [-]: registration refuses points whose 2nd singular value < this x the 1st
GAZE_POINTING_TOL = 1e-9  # [rad]: an eye fixates a target when its optical axis is this close to it
GAZE_PIXEL_FRACTION = (
    0.1  # [px]: with the cameras' focal length known, fixated within this in the image
)


__all__ = [
    "COLLINEAR_TOL",
    "FK_AGREEMENT_TOL",
    "GAZE_PIXEL_FRACTION",
    "GAZE_POINTING_TOL",
    "ROTATION_TOL",
    "UNIT_VECTOR_TOL",
]
