"""ROS-free core."""
