"""``python -m cpc2urdf.validation.gaze.warm``: compile the gaze solve into numba's cache.

What the first use after an install starts in the background (:mod:`.kernels.interpreted`): one
target and a batch on the built-in IIS-head, whose packed head has the types of every head's.
"""

from __future__ import annotations

import numpy as np

from cpc2urdf.validation.gaze import solver_for


def main() -> None:
    solver = solver_for("iis_head")
    solver.solve(np.array([-0.6, -0.6, 0.7]))
    solver.solve_many(np.array([[-0.6, -0.6, 0.7], [-0.5, -0.6, 0.8]]))


if __name__ == "__main__":
    main()
