"""The live dashboard (standard library HTTP + Server-Sent Events); see docs/dashboard.md."""

from statectl.web.server import LOG_SIZE, Dashboard, PostFn
from statectl.web.svg import fallback_svg

__all__ = ["LOG_SIZE", "Dashboard", "PostFn", "fallback_svg"]
