"""Transport, as rosbag2_transport: the tools that move a bag's messages between a ROS graph and
storage, over rclpy. :mod:`.record` (a running line into a bag), :mod:`.play` (a bag's data to a
controller), :mod:`.replay` (a bag's resets and commands into a fresh node, planned by
:mod:`.replay_plan`, compared by :mod:`.compare`), with the tools' own rclpy node
(:mod:`.rosnode`) and progress bars (:mod:`.progress`). Uses :mod:`..storage` and :mod:`..format`.
"""
