"""Pure control logic: SI commands, limits, position control. No Qt."""
