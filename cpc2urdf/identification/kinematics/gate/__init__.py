"""The consistency gates of stage-1 fits: fit statistics, size plausibility, likely mistakes, verdict, diagnosis; the gate of the pose fit and of the calibration about the URDF."""
