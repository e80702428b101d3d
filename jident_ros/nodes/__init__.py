"""ROS 2 nodes of jident_ros: simulator, windowing, diagnostic, replay (docs/interfaces.md).

The ROS adapters over the core (``sim``, ``stream``, ``method``, ``identify``, ``bag``): parameters
(:mod:`.params`), /diagnostics (:mod:`.diagnostics`), message conversions and QoS (:mod:`.ros_io`),
running a node (:mod:`.runtime`).  Only this package and ``cli`` import rclpy.
"""
