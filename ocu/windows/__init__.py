"""Qt windows and docks of the operator console."""
