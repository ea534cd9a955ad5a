"""The OPC UA server's security: who may log in (the one configured user, anonymous clients when allowed),
the server's certificate (made once, self-signed), the security policies and the client certificates trusted."""

from __future__ import annotations

import hmac
import socket
from pathlib import Path
from typing import Any

from asyncua import Server, ua
from asyncua.crypto.cert_gen import setup_self_signed_certificate
from asyncua.crypto.permission_rules import User, UserRole
from asyncua.crypto.truststore import TrustStore
from asyncua.crypto.validator import CertificateValidator, CertificateValidatorOptions
from cryptography.x509.oid import ExtendedKeyUsageOID

from service.errors import OpcUaServerError

from .guard import PEER, Guard
from .settings import OpcUaSettings


class Users:
    """asyncua's user manager: the one configured user (and anonymous clients when allowed); wrong logins and
    throttled hosts are the guard's (``guard.Guard``): every login is tried, a throttled host's more slowly."""

    def __init__(self, username: str | None, password: str | None, anonymous: bool, guard: Guard | None = None) -> None:
        self.username, self.password, self.anonymous = username, password, anonymous
        self.guard = guard

    def get_user(self, iserver: Any, username: str | None = None, password: str | None = None,
                 certificate: Any = None) -> User | None:
        if username is None:
            return User(role=UserRole.User) if self.anonymous else None
        host = PEER.get()
        ok = self.username is not None and self.password is not None and bool(
            hmac.compare_digest(username.encode(), self.username.encode()) & hmac.compare_digest(
                (password or "").encode(), self.password.encode()))
        if not ok and self.guard is not None:
            self.guard.login_failed(host)
        return User(role=UserRole.User, name=username) if ok else None


async def secure(server: Server, s: OpcUaSettings, device_id: str, cert: Path, key: Path) -> None:
    """The application URI, the certificate (``cert``, its private ``key`` readable by the owner only), the
    security policies, the trusted client certificates and the identity tokens accepted."""
    uri = f"urn:moi:{device_id}"
    await server.set_application_uri(uri)
    await setup_self_signed_certificate(key, cert, uri, socket.gethostname(), [ExtendedKeyUsageOID.SERVER_AUTH],
                                        {"countryName": "DE", "organizationName": "moi",
                                         "commonName": f"moi {device_id}"})
    key.chmod(0o600)
    await server.load_certificate(str(cert))
    await server.load_private_key(str(key))
    policies = [ua.SecurityPolicyType.Basic256Sha256_SignAndEncrypt]
    if s.allow_unencrypted:
        policies.append(ua.SecurityPolicyType.NoSecurity)
    server.set_security_policy(policies)
    if s.trusted_clients is not None:
        trusted = Path(s.trusted_clients)
        if not trusted.is_dir():
            raise OpcUaServerError(f"[opcua] trusted_clients {s.trusted_clients!r} is not a directory")
        store = TrustStore([trusted], [])
        await store.load()
        server.set_certificate_validator(CertificateValidator(
            CertificateValidatorOptions.TRUSTED_VALIDATION | CertificateValidatorOptions.PEER_CLIENT, store))
    tokens: list[type] = [ua.UserNameIdentityToken]
    if s.anonymous:
        tokens.append(ua.AnonymousIdentityToken)
    server.set_identity_tokens(tokens)
