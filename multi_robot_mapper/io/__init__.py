"""Files and messages: CARMEN logs, YAML configuration, ROS message conversion, pictures.

May import ``core``; ``core`` never imports this package.
"""
