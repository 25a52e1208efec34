"""move_base-compatible navigation: costmaps with move_base's inflation, scikit-image MCP global planner, vectorised DWA-style local controller, recoveries."""
