"""``jident``: the offline command line (no ROS needed), the demo and the offline diagnosis."""
