"""Pure algorithms over numpy arrays. Nothing in this package may import rclpy or ROS messages.

Pipeline stages, in order: ``scan`` (beams to points) -> ``extraction`` (points to segments)
-> local mapping -> matching -> merging -> output.
"""
