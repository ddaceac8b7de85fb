"""ROS 1 bridge: a ROS-free core (`bridge`), the rospy wrapper (`rosbridge`), the node (`node`).

Importing this package imports no ROS; `ocu.ros.bridge` (with `convert` and `diagnostics`)
imports neither ROS nor Qt.
"""
