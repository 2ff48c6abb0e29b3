"""Checking and using a model: URDF cross-checks, accuracy, gaze control, 3D view.

Installed as ``cpc2urdf.validation``; import it by that name only.
"""
