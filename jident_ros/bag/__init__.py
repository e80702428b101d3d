"""Recordings: writing rosbag2-compatible MCAP bags, reading them, and salvaging cut-off ones."""
