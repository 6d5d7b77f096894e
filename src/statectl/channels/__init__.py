"""The ways in: the command line, the dashboard, OPC UA and Zenoh nodes.

Each channel parses what arrives and hands events to a :class:`~statectl.run.system.System`.
"""
