"""Maps and mapcells, ROS-free: :mod:`~cnr_maps.mapio`, :mod:`~cnr_maps.grid`, :mod:`~cnr_maps.measurements`,
:mod:`~cnr_maps.pose`."""
