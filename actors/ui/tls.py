"""The UI's certificate: the user's own files, an identity from the EMOS keystore, or a
self-signed one made here with ``cryptography`` (no crypto of our own).

The self-signed certificate is kept in ``$EMOS_HOME/ui/tls/`` (directory 0700, key 0600) and
reused while it is valid and names every address asked for, so a browser that accepted it once
keeps accepting it. Its SHA-256 fingerprint is printed at start-up: compare it with the one the
browser shows before accepting the certificate.
"""
from __future__ import annotations

import datetime
import hashlib
import ipaddress
import os
import socket
import ssl
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from emos.errors import ConfigError

VALID_DAYS = 825  # the longest validity browsers accept for a server certificate
ENV_HOME = "EMOS_HOME"


def tls_home() -> Path:
    return Path(os.environ.get(ENV_HOME) or Path.home() / "emos").expanduser() / "ui" / "tls"


def machine_names(bind_host: str) -> list[str]:
    """The names and addresses a browser may use for a server bound to ``bind_host``."""
    host = socket.gethostname()
    names = {"localhost", "127.0.0.1", "::1", host, f"{host}.local"}
    if bind_host not in ("0.0.0.0", "::", ""):
        names.add(bind_host.strip("[]"))
    else:
        try:
            import psutil

            for addrs in psutil.net_if_addrs().values():
                for a in addrs:
                    if a.family in (socket.AF_INET, socket.AF_INET6):
                        names.add(a.address.split("%", 1)[0])
        except Exception:  # psutil missing or no interfaces readable: the host name still works
            pass
    return sorted(names)


def _san(names: Iterable[str]) -> Any:
    from cryptography import x509

    entries: list[Any] = []
    for n in names:
        try:
            entries.append(x509.IPAddress(ipaddress.ip_address(n)))
        except ValueError:
            entries.append(x509.DNSName(n))
    return x509.SubjectAlternativeName(entries)


def _names_of(cert: Any) -> set[str]:
    from cryptography import x509

    try:
        san = cert.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    except x509.ExtensionNotFound:
        return set()
    return {str(v) for v in san.get_values_for_type(x509.IPAddress)} | set(san.get_values_for_type(x509.DNSName))


def self_signed(names: list[str], folder: Path | None = None) -> tuple[Path, Path]:
    """(certificate, key) for ``names``: reused if the one in ``folder`` still fits, else made."""
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import NameOID

    folder = folder or tls_home()
    folder.mkdir(parents=True, exist_ok=True, mode=0o700)
    os.chmod(folder, 0o700)
    cert_path, key_path = folder / "ui-selfsigned.crt", folder / "ui-selfsigned.key"
    now = datetime.datetime.now(datetime.UTC)
    try:
        cert = x509.load_pem_x509_certificate(cert_path.read_bytes())
        if key_path.is_file() and set(names) <= _names_of(cert) and cert.not_valid_after_utc > now + datetime.timedelta(days=7):
            return cert_path, key_path
    except (OSError, ValueError):
        pass
    key = ec.generate_private_key(ec.SECP256R1())
    subject = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, f"EMOS UI on {socket.gethostname()}"[:64]),
                         x509.NameAttribute(NameOID.ORGANIZATION_NAME, "EMOS (self-signed)")])
    cert = (x509.CertificateBuilder().subject_name(subject).issuer_name(subject).public_key(key.public_key())
            .serial_number(x509.random_serial_number()).not_valid_before(now - datetime.timedelta(minutes=5))
            .not_valid_after(now + datetime.timedelta(days=VALID_DAYS)).add_extension(_san(names), critical=False)
            .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
            .add_extension(x509.ExtendedKeyUsage([x509.oid.ExtendedKeyUsageOID.SERVER_AUTH]), critical=False)
            .sign(key, hashes.SHA256()))
    pem_key = key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8, serialization.NoEncryption())
    tmp = key_path.with_name(f".{key_path.name}.{os.getpid()}")
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_NOFOLLOW, 0o600)
    with os.fdopen(fd, "wb") as f:
        f.write(pem_key)
    os.replace(tmp, key_path)
    tmp = cert_path.with_name(f".{cert_path.name}.{os.getpid()}")
    tmp.write_bytes(cert.public_bytes(serialization.Encoding.PEM))
    os.replace(tmp, cert_path)
    return cert_path, key_path


def from_keystore(keystore: str, identity: str) -> tuple[Path, Path]:
    """(certificate, key) of ``identity`` in the EMOS keystore (``emos security create-identity``)."""
    load_identity: Any = None
    for module in ("emos.security", "emos.security.keystore", "emos.transport.zenoh_security"):
        try:
            load_identity = getattr(__import__(module, fromlist=["load_identity"]), "load_identity", None)
        except ImportError:
            continue
        if load_identity is not None:
            break
    if load_identity is None:
        raise ConfigError(f"UIConfig.keystore={keystore!r}: this EMOS has no keystore support (emos security); "
                          "give certfile and keyfile instead")
    cert, key, _ca = load_identity(keystore, identity)
    return Path(cert), Path(key)


def fingerprint(cert_path: Path) -> str:
    """SHA-256 of the certificate (DER), as browsers show it: ``AB:CD:...``."""
    der = ssl.PEM_cert_to_DER_cert(Path(cert_path).read_text())
    digest = hashlib.sha256(der).hexdigest().upper()
    return ":".join(digest[i:i + 2] for i in range(0, len(digest), 2))


def server_context(cert_path: str, key_path: str) -> ssl.SSLContext:
    """The server's TLS context (TLS 1.2 or newer); a clear error if the files do not fit."""
    ctx = ssl.create_default_context(ssl.Purpose.CLIENT_AUTH)
    ctx.minimum_version = ssl.TLSVersion.TLSv1_2
    try:
        ctx.load_cert_chain(cert_path, key_path)
    except (OSError, ssl.SSLError) as exc:
        raise ConfigError(f"the UI's certificate {cert_path} with key {key_path} cannot be used: {exc}") from None
    return ctx
