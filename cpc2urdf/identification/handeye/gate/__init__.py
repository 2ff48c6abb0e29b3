"""The hand-eye consistency gate: tested mistakes, the gate's own fit, the report."""
