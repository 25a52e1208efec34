"""Bring-up of the simulated TurtleBot 2 and the launcher the workspace's scripts use (``cnr_launch``)."""
