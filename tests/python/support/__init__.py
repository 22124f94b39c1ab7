"""The Python tests' helpers that are not tests themselves (tests/python/support/).

Imported as ``from support import ros_harness as h`` or ``from support.line_client import LineClient``
(tests/python/conftest.py puts tests/python on sys.path). What each module is for is its own docstring:
the ROS harness (node processes, the rclpy session, trace views), the lock-step line client, the ros2
CLI, the network-namespace "hosts", the golden bags, the colcon workspace, Foxglove's readers, DDS
participant ids, foreign bags, RTPS datagrams, the scripted controller (a script started by path), the
training-stack marker, the RIHS01 type hashes, and what several test modules share (the env-against-trace
checks, the controller process, the node's diagnostics, the Ray cluster, the image checks), and the one
wait that spins no rclpy (waits.wait_until).
No module here is collected by pytest (none is named test_*).
"""
