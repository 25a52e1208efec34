"""ROS-free statistics and report writing for the benchmarks."""
