"""A cell spread over processes and machines, its links carried by Eclipse Zenoh.

:mod:`~statectl.distributed.system` is one node's System (its own devices, the
links to the others handed to the wire); :mod:`~statectl.distributed.wire` is the
Zenoh side (link streams, acknowledgements, presence, published states);
:mod:`~statectl.distributed.streams` numbers and deduplicates a stream without
I/O; :mod:`~statectl.distributed.keys` names the key expressions. Zenoh
(``eclipse-zenoh``, the ``zenoh`` extra) is imported only when a node opens.
See docs/distributed.md.
"""

from statectl.distributed.keys import Keys
from statectl.distributed.streams import Inbound, Outbound, Verdict
from statectl.distributed.system import NodeLinks, NodeSystem
from statectl.distributed.wire import Wire

__all__ = ["Inbound", "Keys", "NodeLinks", "NodeSystem", "Outbound", "Verdict", "Wire"]
