"""cnr_store_forward: disk-backed, exactly-once, ordered store-and-forward of a ROS topic (see the README)."""
