"""A cell spread over processes and machines, its links carried by Eclipse Zenoh.

:mod:`~statectl.channels.distributed.system` is one node's System (its own devices, the
links to the others handed to the wire); :mod:`~statectl.channels.distributed.wire` is the
Zenoh side (link streams, acknowledgements, presence, published states);
:mod:`~statectl.channels.distributed.streams` numbers and deduplicates a stream without
I/O; :mod:`~statectl.channels.distributed.keys` names the key expressions. Zenoh
(``eclipse-zenoh``, the ``zenoh`` extra) is imported only when a node opens.
See docs/distributed.md.
"""

from statectl.channels.distributed.keys import Keys
from statectl.channels.distributed.streams import Inbound, Outbound, Verdict
from statectl.channels.distributed.system import NodeLinks, NodeSystem
from statectl.channels.distributed.wire import Wire

__all__ = ["Inbound", "Keys", "NodeLinks", "NodeSystem", "Outbound", "Verdict", "Wire"]
