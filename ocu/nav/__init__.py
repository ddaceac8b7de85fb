"""Driving with a map, pure (no Qt, no sockets): geometry and the simulator's world, odometry,
range scans and the occupancy grid, seed 002's safety zones, Samson's tracking controller
and the assisted modes, and the Navigator that combines them for the console and ROS.
"""
