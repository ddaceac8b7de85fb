"""The session served live over the Foxglove WebSocket protocol (docs/live.md)."""
