"""ocu: an Operator Control Unit for the Servosila Engineer crawler robot."""

__version__ = "0.1.0"
