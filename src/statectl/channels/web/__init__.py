"""The live dashboard (aiohttp + Server-Sent Events on its own loop); see docs/dashboard.md."""

from statectl.channels.web.app import Limits
from statectl.channels.web.server import LOG_SIZE, Dashboard, PostFn
from statectl.channels.web.svg import fallback_svg

__all__ = ["LOG_SIZE", "Dashboard", "Limits", "PostFn", "fallback_svg"]
