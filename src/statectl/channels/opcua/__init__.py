"""``statectl run --opcua``: the running devices as an OPC UA address space (asyncua).

:mod:`statectl.channels.opcua.space` works out the machines and numbers from a chart;
:mod:`statectl.channels.opcua.server` serves them on their own loop thread;
:mod:`statectl.channels.opcua.packml` names a ``profile: packml`` device as OPC 30050
does. asyncua is the
``opcua`` extra: ``pip install 'statectl[opcua]'``.
"""

from statectl.channels.opcua.space import Layout, MachineSpec, layout

__all__ = ["Layout", "MachineSpec", "layout"]
