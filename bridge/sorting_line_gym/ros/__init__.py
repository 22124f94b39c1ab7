"""The rclpy layer: rclpy once per process and never across a fork (``context``), waits with
deadlines (``waits``), one line's and all lines' endpoints (``links``), the batch messages as numpy
records (``batch_codec``), and the bank of lines an environment drives (``bank``).

Importing it needs the ROS environment (``source launch_scripts/env.sh``); the environments import
it when the first one is made, so ``import sorting_line_gym`` does not."""
