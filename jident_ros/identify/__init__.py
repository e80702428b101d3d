"""From a window to a verdict: the gap (physics) estimator, the fusion with the image method, the
per-window diagnosis, the pattern library's home, and the trend of J1 and K2 over time. Plain
numpy/scipy, never imports rclpy."""
