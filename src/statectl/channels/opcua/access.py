"""Who may do what on the OPC UA server (rule 4 of :mod:`statectl.channels.opcua.server`):
anonymous clients browse, read and subscribe; the one configured user may also call
methods; nobody writes. Passwords are compared in constant time.
"""

from __future__ import annotations

import hmac
from typing import Any

__all__ = ["Users", "rules", "ua_module"]


class Users:
    """Rule 4: anonymous is anonymous; the one configured user may call methods."""

    def __init__(self, user: str | None, password: str | None) -> None:
        self._user, self._password = user, password

    def get_user(
        self, iserver: Any, username: str | None = None, password: str | None = None,
        certificate: Any = None,
    ) -> Any:  # fmt: skip
        from asyncua.crypto.permission_rules import User, UserRole

        if username is None and password is None:  # an anonymous token (maybe a channel cert)
            return User(role=UserRole.Anonymous)
        if (
            self._user is not None
            and self._password is not None
            and username is not None
            and password is not None
            and hmac.compare_digest(username.encode(), self._user.encode())
            and hmac.compare_digest(_bytes(password), self._password.encode())
        ):
            return User(role=UserRole.User, name=username)
        return None  # wrong credentials: the session is refused


def ua_module() -> Any:
    """asyncua's ``ua`` module, untyped here: asyncua is optional and its stubs are partial."""
    from asyncua import ua

    return ua


def _bytes(text: str | bytes) -> bytes:
    return text if isinstance(text, bytes) else text.encode()


def rules() -> Any:  # a ruleset class built on first use (asyncua is optional)
    ua = ua_module()
    from asyncua.crypto.permission_rules import USER_TYPES, PermissionRuleset, UserRole

    call = ua.NodeId(ua.ObjectIds.CallRequest_Encoding_DefaultBinary)
    write = ua.NodeId(ua.ObjectIds.WriteRequest_Encoding_DefaultBinary)
    everyone = {ua.NodeId(t) for t in USER_TYPES} - {call, write}

    class Rules(PermissionRuleset):
        """Anonymous: browse, read, subscribe. The user: that and call. Nobody writes."""

        def check_validity(self, user: Any, action_type_id: Any, body: Any) -> bool:
            role = getattr(user, "role", None)
            if role is UserRole.User:
                return action_type_id in everyone or action_type_id == call
            return role is UserRole.Anonymous and action_type_id in everyone

    return Rules()
