"""The rospy process runtime shared by every node (see :mod:`cnr_runtime.node`)."""
from cnr_runtime.node import (CALLERID_SUFFIX_ENV, BackgroundCall, call_with_timeout, distinct_callerid,  # noqa: F401
                              init_node, quiet_at_shutdown)
