"""First contact with a robot: probe what arrives, calibrate, write a profile (no Qt)."""
