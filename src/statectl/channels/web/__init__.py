"""The live dashboard (aiohttp + Server-Sent Events on its own loop); see docs/dashboard.md.

:mod:`~statectl.channels.web.server` is the :class:`Dashboard` (aiohttp, the ``dashboard``
extra), :mod:`~statectl.channels.web.app` its routes and :class:`Limits`,
:mod:`~statectl.channels.web.config` the run config's ``dashboard:`` section. Nothing is
imported here, so reading a run config needs no aiohttp.
"""
