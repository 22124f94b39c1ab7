"""The controller check (`sorting-line-bag check`), above transport: :mod:`.checker` (the entry,
``check_controller``), :mod:`.open_loop` (the bag played to the controller, its answers compared),
:mod:`.closed_loop` (the controller drives a fresh node, episodes compared), :mod:`.verdict` (the
result: exit code, summary, JSON, JUnit XML; no ROS), :mod:`.controller_process` (the controller
as a child process) and :mod:`.options` (what every run of a check takes).

Nothing is imported here, so that :mod:`.verdict` stays usable without rclpy.
"""
