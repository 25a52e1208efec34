"""ROS-free simulator core: map loading, kinematics, ray casting, battery model, world stepping."""
