"""ROS-free core of network_monitor: RTT echo statistics, interface counters, interface choice, the iperf3
probe, the passive A_bw estimate and R_bw (thesis Eq. 4-1); and the network-aware migration decision (thesis
§4.2.5-§4.2.6): training sets (training.py), the k-NN decision (decision.py), evaluation and labelling
(evaluation.py), mid-task re-decision (hysteresis.py) and its configuration (decision_config.py). Nothing here
imports rospy or reads a clock: every time is an argument."""
