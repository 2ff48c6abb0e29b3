"""From measurements to parameters: plate pose estimation, CPC identification, hand-eye.

Installed as ``cpc2urdf.identification``; import it by that name only.
"""
