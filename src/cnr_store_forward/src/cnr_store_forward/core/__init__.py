"""ROS-free core of cnr_store_forward: the disk queue, the go-back-N sender, the deduplicating receiver and
the parameters. Nothing here imports rospy or reads a clock: every time is an argument."""
