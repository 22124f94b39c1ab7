"""The bridge's two errors, raised by every layer (no ROS needed to import or catch them)."""


class BridgeError(RuntimeError):
    """The node or the link to it failed (the node exited, a reset was refused, ...)."""


class BridgeTimeout(BridgeError, TimeoutError):
    """A wait ran out of time; the message names what was waited for."""
