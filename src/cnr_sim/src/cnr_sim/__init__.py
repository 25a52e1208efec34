"""Stage-like simulated TurtleBot 2 (Kobuki base, Kinect fake laser) and a map_server work-alike."""
