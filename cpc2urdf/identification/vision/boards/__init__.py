"""Standard calibration boards: definition, board files, detection and poses."""
