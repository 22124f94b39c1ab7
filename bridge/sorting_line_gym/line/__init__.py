"""The line without ROS: its vocabulary (setups, speeds, modes, the spaces' numbers), the options an
environment is made with, the errors, the node as a child process, and what the environments of one
host share (state directory, line servers, the lock for joining the graph), and how the
command-line tools hand their flags to the functions they front.

Nothing here imports rclpy or Stable-Baselines3: every other layer builds on it."""
