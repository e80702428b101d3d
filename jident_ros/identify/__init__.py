"""From a window to a verdict: the gap (physics) estimator, the fusion with the image method, the
per-window diagnosis, and the pattern library's home. Plain numpy/scipy, never imports rclpy."""
