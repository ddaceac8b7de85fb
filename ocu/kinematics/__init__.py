"""Arm kinematics on the URDF tree (numpy only): chains, IK, self-collision, trajectories.

- `chain`: forward kinematics and the Jacobian of any chain between two links of a
  `ocu.model.tree.KinematicTree`;
- `analytic`: the geometric inverse kinematics of a yaw joint plus three parallel pitch joints
  (seed 003 §2.3; the Engineer's waist, shoulder, elbow and neck);
- `numeric`: a damped-least-squares solver over any chain (any other robot);
- `collision`: capsules and boxes per link from the URDF's geometry, distances between them;
- `trajectory`: synchronized trapezoidal and cubic joint profiles;
- `rpy`: a whole pose as x, y, z, roll, pitch, yaw (ROS's convention) and back;
- `arm`: the arm as the console sees it (tool pose as x, y, z and pitch, the 4-row Jacobian,
  the workspace slice), built from a robot model and the profile's `[arm]` table.
"""
