"""ROS-free core of network_monitor: RTT echo statistics, interface counters, interface choice, the iperf3
probe, the passive A_bw estimate and R_bw (thesis Eq. 4-1). Nothing here imports rospy or reads a clock:
every time is an argument."""
