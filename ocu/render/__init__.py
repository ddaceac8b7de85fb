"""Drawing the robot model with OpenGL, in a Qt widget or offscreen through OSMesa.

Importing this package does not import OpenGL: PyOpenGL's platform must be chosen first
(ocu.render.platform), and only ocu.render.gl imports it.
"""
