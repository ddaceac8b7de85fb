"""Hardware plug-ins: each robot as a hardware component (ocu.core.hardware), by name."""
