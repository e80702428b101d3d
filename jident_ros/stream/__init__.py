"""The drive's data stream: topic names and channel layouts, the backlash-entry detector(s),
and the input adapters. Plain numpy, never imports rclpy."""
