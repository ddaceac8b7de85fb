"""The link to the robot: a Qt-free core (core.py) and its QThread adapter (qt.py)."""
