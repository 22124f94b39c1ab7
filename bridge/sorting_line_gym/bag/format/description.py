"""What a sorting_line bag keeps about itself besides its messages: in metadata.yaml's
``custom_data`` (and, for recovery, in each MCAP file's metadata record of the same name) the
line's description under :data:`META_KEY` (:class:`LineInfo`: the line's namespace and the options
of the node that served it, so that ``sorting-line-bag replay BAG`` needs nothing else), the
recording's own description under :data:`RECORDING_KEY`, and the reserve file a recorder keeps in
the bag directory for writing the end of a bag after the disk filled."""

from __future__ import annotations

import json
from dataclasses import dataclass, field

#: The custom_data key (and MCAP metadata record) of the line's description.
META_KEY = "sorting_line"
#: The MCAP metadata record of the line's description.
META_RECORD = META_KEY
#: custom_data key of the recording itself: options, state (recording, closed, failed) and what
#: was lost (see :mod:`sorting_line_gym.bag.storage.losses`).
RECORDING_KEY = "sorting_line_recording"
#: The space a recorder holds back in the bag directory (removed when the bag is closed).
RESERVE_NAME = ".sorting_line_reserve"


@dataclass
class LineInfo:
    """What a bag says about the line it recorded."""

    namespace: str
    #: The node's options as `sorting_line node` flags take them (underscores), with ``seed`` the
    #: seed of this line (node seed + line index).
    node: dict = field(default_factory=dict)
    #: Bags of other recorders: where each option in ``node`` came from (empty: custom_data).
    sources: dict = field(default_factory=dict)

    def to_json(self) -> str:
        return json.dumps({"namespace": self.namespace, "node": self.node}, sort_keys=True)

    @classmethod
    def from_json(cls, text: str) -> LineInfo:
        data = json.loads(text)
        return cls(namespace=data["namespace"], node=dict(data.get("node") or {}))
