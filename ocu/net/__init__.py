"""Network plumbing shared by the link and the simulator: transports and the select loop."""
