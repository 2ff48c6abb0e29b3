"""Position-only data (marker points): residuals, circle-point start, refinement, gate, identification."""
