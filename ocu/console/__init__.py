"""The console model: the whole command and what is known of the robot, no Qt (napari-style)."""
