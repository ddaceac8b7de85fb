"""Qt widgets of the console: telemetry table, 3D model, video."""
