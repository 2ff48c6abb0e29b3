"""Denavit-Hartenberg to CPC conversion.

Standard DH: ``A_i = Rot(z, theta_i) Trans(z, d_i) Trans(x, a_i) Rot(x, alpha_i)`` maps DH frame
i-1 (z on joint i's axis) to DH frame i (z on joint i+1's axis). The joint variable is theta_i
(revolute) or d_i (prismatic). Both Rot(z, .) and Trans(z, .) commute with the joint motion, so

    A_i(q_i) = Q_i(q_i) @ C_i,   C_i = Rot(z, theta_i^0) Trans(z, d_i^0) Trans(x, a_i) Rot(x, alpha_i)

where theta_i^0 / d_i^0 are the constant parts (0 for the joint variable itself). ``C_i`` is a
rigid transform, and every rigid transform whose z image is not exactly ``-z`` has exact CPC
constants (``CPCParams.from_matrix``). The conversion is therefore exact for every DH chain,
including parallel consecutive axes (alpha = 0), where DH's own parameters jump under tiny
misalignment but the CPC constants of the same geometry stay continuous.
"""

from __future__ import annotations

import math

import numpy as np

from cpc2urdf.model import CPCParams
from cpc2urdf.transforms import Array


def dh_matrix(theta: float, d: float, a: float, alpha: float) -> Array:
    """``Rot(z, theta) Trans(z, d) Trans(x, a) Rot(x, alpha)``; angles [rad], lengths [m]."""
    ct, st, ca, sa = math.cos(theta), math.sin(theta), math.cos(alpha), math.sin(alpha)
    return np.array(
        [
            [ct, -st * ca, st * sa, a * ct],
            [st, ct * ca, -ct * sa, a * st],
            [0.0, sa, ca, d],
            [0.0, 0.0, 0.0, 1.0],
        ]
    )


def cpc_from_dh(theta: float, d: float, a: float, alpha: float) -> CPCParams:
    """CPC constants of a DH row's constant part ``C_i`` (see module doc).

    Args:
        theta: Constant joint angle [rad]; pass 0 when theta is the revolute joint variable.
        d: Constant offset [m]; pass 0 when d is the prismatic joint variable.
        a: Link length [m].
        alpha: Link twist [rad]. |alpha| = pi (anti-parallel axes) is the CPC singular case;
            it is still converted exactly (see ``cpc_rotation``).
    """
    return CPCParams.from_matrix(dh_matrix(theta, d, a, alpha))


__all__ = [
    "cpc_from_dh",
    "dh_matrix",
]
