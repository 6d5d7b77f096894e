"""Who may do what on the OPC UA server (rule 4 of :mod:`statectl.channels.opcua.server`).

Rules:
1. Anonymous clients browse, read and subscribe, and may call ``ConditionRefresh``
   (a request whose every method is ``ConditionRefresh`` or ``ConditionRefresh2``:
   it only sends the caller's subscription the retained alarms again); the one
   configured user may also call methods; nobody writes. Passwords are compared in
   constant time.
2. Only the security policies the config lists open a session. asyncua picks a
   channel's policy from its factories and, when none matches, keeps the policy the
   connection started with: None, with no permission rules at all. So when the config
   does not list None, :func:`discovery_only` is a factory for it whose channels serve
   the discovery services (GetEndpoints, FindServers: a client reads the endpoints and
   the server's certificate that way) and refuse everything else with
   ``BadSecurityPolicyRejected``: CreateSession, ActivateSession and every service of a
   session.
3. The ruleset sees every request of a session, with the session's user, just before
   it runs: it notes that user for the request (:func:`caller`), so a method handler,
   which asyncua calls without the session, authorises the call against it. A request
   that the ruleset did not see has no caller: anonymous.
"""

from __future__ import annotations

import hmac
from contextvars import ContextVar
from typing import Any

__all__ = ["Users", "caller", "discovery_only", "rules", "ua_module"]

#: The user of the session whose request this task is serving (rule 3); None: anonymous.
#: asyncua serves each connection's requests one at a time on the connection's own task.
_CALLER: ContextVar[str | None] = ContextVar("statectl_opcua_caller", default=None)


def caller() -> str | None:
    """The user of the session whose request is being served (rule 3); None: anonymous."""
    return _CALLER.get()


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
            _CALLER.set(getattr(user, "name", None) if role is UserRole.User else None)  # rule 3
            if role is UserRole.User:
                return action_type_id in everyone or action_type_id == call
            if role is UserRole.Anonymous and action_type_id == call:
                return _refresh_only(body)
            return role is UserRole.Anonymous and action_type_id in everyone

    return Rules()


def _refresh_only(body: Any) -> bool:
    """Rule 1: a Call request whose every method is a ConditionRefresh (read from a copy
    of the request's bytes: asyncua reads the body itself afterwards)."""
    ua = ua_module()
    from asyncua.common.utils import Buffer
    from asyncua.ua.ua_binary import struct_from_binary

    refresh = {
        ua.NodeId(ua.ObjectIds.ConditionType_ConditionRefresh),
        ua.NodeId(ua.ObjectIds.ConditionType_ConditionRefresh2),
    }
    try:
        params = struct_from_binary(ua.CallParameters, Buffer(bytes(body)))
    except Exception:  # unreadable: asyncua refuses it on its own reading
        return False
    methods = params.MethodsToCall or []
    return bool(methods) and all(m.MethodId in refresh for m in methods)


def discovery_only() -> Any:
    """Rule 2: the factory of the None policy for a server whose config does not list it."""
    from asyncua.common.utils import ServiceError
    from asyncua.crypto.permission_rules import PermissionRuleset
    from asyncua.crypto.security_policies import CryptographyNone, SecurityPolicyNone

    rejected = ua_module().StatusCodes.BadSecurityPolicyRejected

    class Refused(PermissionRuleset):
        """Every service of a session on such a channel (the discovery ones never get here)."""

        def check_validity(self, user: Any, action_type_id: Any, body: Any) -> bool:
            raise ServiceError(rejected)

    class NoSession(CryptographyNone):
        """ActivateSession verifies the client's signature with this: refused."""

        def verify(self, data: Any, signature: Any) -> None:
            raise ServiceError(rejected)

    class Discovery(SecurityPolicyNone):
        """A None channel that discovers: CreateSession reads the signature algorithm of
        the policy to answer, and is refused there, before the answer is sent."""

        def __init__(self, peer_certificate: Any) -> None:
            base: Any = super().__init__  # asyncua's policies are untyped
            base(peer_certificate, permission_ruleset=Refused())
            self.asymmetric_cryptography = NoSession()  # type: ignore[no-untyped-call]

        @property
        def AsymmetricSignatureURI(self) -> str:  # type: ignore[override]  # a str there
            raise ServiceError(rejected)

    class Factory:
        """What asyncua asks a server's policy factories: does it match, then make one."""

        def matches(self, uri: str, mode: Any = None) -> bool:
            return uri == SecurityPolicyNone.URI

        def create(self, peer_certificate: Any) -> Any:
            return Discovery(peer_certificate)

    return Factory()
