"""A keystore: one certificate authority and the identities it signs (robots, hosts, operators).

Layout (directories 0700, files 0600, created with ``O_EXCL`` so that nothing is ever
overwritten)::

    KEYSTORE/
      keystore.json                 what this directory is (checked before anything is read)
      ca/ca.crt  ca/ca.key          the CA: its certificate, its private key (never leaves here)
      identities/NAME/NAME.crt      NAME's certificate (CN = NAME, signed by the CA)
      identities/NAME/NAME.key      NAME's private key
      policies/                     Zenoh configurations written by ``emos security policy``

Every key is ECDSA P-256 in PKCS#8 PEM; certificates are X.509 v3 made with the
``cryptography`` package (no home-made crypto). An identity's certificate is valid for both TLS
roles (``serverAuth`` and ``clientAuth``): a Zenoh peer both listens and connects. Its subject
alternative names are its name when that is a valid host name, plus the host names and
addresses given with ``hosts=`` (a peer that connects with ``verify_name_on_connect`` checks the
address it dialled against them).

:func:`load_identity` is the one way to use an identity (Zenoh's TLS here, the web UI's HTTPS):
it returns the paths of its certificate, key and CA certificate after checking that the files
are ours with private modes, that the certificate is the CA's, names ``NAME`` and is valid now.
"""
from __future__ import annotations

import datetime
import ipaddress
import json
import os
import re
import stat
from pathlib import Path
from typing import Any

from emos.errors import EmosError

__all__ = ["KeystoreError", "create_keystore", "create_identity", "load_identity", "identity_names", "ca_certificate_path",
           "CA_DAYS", "IDENTITY_DAYS"]

CA_DAYS = 3650  # a CA outlives the identities it signs: renewing it means re-issuing every one
IDENTITY_DAYS = 365
MAX_DAYS = 3650 * 3
_CLOCK_SKEW = datetime.timedelta(minutes=5)  # not-before this much in the past: hosts' clocks differ
_NAME_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,62}$")  # a file name and a certificate CN
_HOST_LABEL_RE = re.compile(r"^(?!-)[A-Za-z0-9-]{1,63}(?<!-)$")
_MARKER = "keystore.json"
_FORMAT = 1


class KeystoreError(EmosError, ValueError):
    """A keystore or identity that cannot be created or used; the message names the file and
    what was expected."""


# ------------------------------------------------------------------------------------ helpers
def _crypto() -> Any:
    try:
        from cryptography import x509
        from cryptography.hazmat.primitives import hashes, serialization
        from cryptography.hazmat.primitives.asymmetric import ec
        from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID
    except ImportError:
        raise KeystoreError("emos security needs the 'cryptography' package: pip install cryptography") from None
    return x509, hashes, serialization, ec, ExtendedKeyUsageOID, NameOID


def check_name(name: str, what: str = "identity name") -> str:
    if not isinstance(name, str) or not _NAME_RE.match(name):
        raise KeystoreError(f"{what} must be 1-63 letters, digits, '_', '.' or '-' (starting with a letter or digit), got {name!r}")
    return name


def _is_hostname(name: str) -> bool:
    return len(name) <= 253 and all(_HOST_LABEL_RE.match(label) for label in name.split("."))


def _mkdir_private(path: Path) -> None:
    """Create ``path`` (0700); fail if it exists."""
    try:
        path.mkdir(mode=0o700)
    except FileExistsError:
        raise KeystoreError(f"{path} already exists: refusing to overwrite it") from None
    os.chmod(path, 0o700)  # mkdir's mode is masked by the umask


def _write_private(path: Path, data: bytes) -> None:
    """Write a new file of mode 0600; never replaces one (O_EXCL) nor follows a link."""
    try:
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW | os.O_CLOEXEC, 0o600)
    except FileExistsError:
        raise KeystoreError(f"{path} already exists: refusing to overwrite it") from None
    try:
        os.fchmod(fd, 0o600)
        view = memoryview(data)
        while view:
            view = view[os.write(fd, view):]
    finally:
        os.close(fd)


def _check_private(path: Path, kind: str, mode_mask: int) -> None:
    """``path`` is a ``kind`` ('file' or 'dir') of ours, not a link, with no bit of ``mode_mask``."""
    try:
        st = os.lstat(path)
    except FileNotFoundError:
        raise KeystoreError(f"{path} does not exist") from None
    ok_kind = stat.S_ISDIR(st.st_mode) if kind == "dir" else stat.S_ISREG(st.st_mode)
    if not ok_kind:
        raise KeystoreError(f"{path} is not a {'directory' if kind == 'dir' else 'regular file'} (a link or another kind of file)")
    if st.st_uid != os.geteuid():
        raise KeystoreError(f"{path} is owned by uid {st.st_uid}, not by this user ({os.geteuid()}): refusing to use it")
    if st.st_mode & mode_mask:
        raise KeystoreError(f"{path} has mode {stat.S_IMODE(st.st_mode):o}: other users may read or change it "
                            f"(expected {'0700' if kind == 'dir' else '0600'}; chmod it)")


def _read(path: Path) -> bytes:
    with open(path, "rb") as f:
        return f.read()


def _now() -> datetime.datetime:
    return datetime.datetime.now(datetime.UTC)


def _new_key() -> Any:
    _, _, _, ec, _, _ = _crypto()
    return ec.generate_private_key(ec.SECP256R1())


def _key_pem(key: Any) -> bytes:
    _, _, serialization, _, _, _ = _crypto()
    pem: bytes = key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8, serialization.NoEncryption())
    return pem


# ------------------------------------------------------------------------------------ keystore
def _check_keystore(keystore: str | os.PathLike[str]) -> Path:
    root = Path(keystore).expanduser().absolute()
    _check_private(root, "dir", 0o077)
    marker = root / _MARKER
    _check_private(marker, "file", 0o022)
    try:
        fmt = json.loads(_read(marker)).get("format")
    except (OSError, ValueError, AttributeError) as exc:
        raise KeystoreError(f"{marker} is not an EMOS keystore marker: {exc}") from None
    if fmt != _FORMAT:
        raise KeystoreError(f"{marker}: keystore format {fmt!r}, this EMOS reads format {_FORMAT}")
    return root


def ca_certificate_path(keystore: str | os.PathLike[str]) -> Path:
    return _check_keystore(keystore) / "ca" / "ca.crt"


def create_keystore(keystore: str | os.PathLike[str], common_name: str = "EMOS CA", days: int = CA_DAYS) -> Path:
    """Create a keystore with a new CA in ``keystore`` (which must not exist, or be an empty
    directory of ours). Returns the CA certificate's path."""
    x509, hashes, _, _, _, NameOID = _crypto()
    if not isinstance(days, int) or isinstance(days, bool) or not 1 <= days <= MAX_DAYS:
        raise KeystoreError(f"CA validity must be 1..{MAX_DAYS} days, got {days!r}")
    root = Path(keystore).expanduser().absolute()
    if root.exists() or root.is_symlink():
        _check_private(root, "dir", 0o022)
        if any(root.iterdir()):
            raise KeystoreError(f"{root} already exists and is not empty: refusing to overwrite it (a keystore there would lose its CA)")
        os.chmod(root, 0o700)
    else:
        root.parent.mkdir(parents=True, exist_ok=True)
        _mkdir_private(root)
    key = _new_key()
    name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, common_name), x509.NameAttribute(NameOID.ORGANIZATION_NAME, "EMOS")])
    now = _now()
    cert = (
        x509.CertificateBuilder().subject_name(name).issuer_name(name).public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - _CLOCK_SKEW).not_valid_after(now + datetime.timedelta(days=days))
        .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
        .add_extension(x509.KeyUsage(digital_signature=False, content_commitment=False, key_encipherment=False, data_encipherment=False,
                                     key_agreement=False, key_cert_sign=True, crl_sign=True, encipher_only=False, decipher_only=False), critical=True)
        .add_extension(x509.SubjectKeyIdentifier.from_public_key(key.public_key()), critical=False)
        .sign(key, hashes.SHA256())
    )
    _mkdir_private(root / "ca")
    _write_private(root / "ca" / "ca.key", _key_pem(key))
    _write_private(root / "ca" / "ca.crt", cert.public_bytes(_pem()))
    _mkdir_private(root / "identities")
    _mkdir_private(root / "policies")
    _write_private(root / _MARKER, json.dumps({"format": _FORMAT, "kind": "emos-keystore", "ca": "ca/ca.crt"}).encode() + b"\n")
    return root / "ca" / "ca.crt"


def _pem() -> Any:
    _, _, serialization, _, _, _ = _crypto()
    return serialization.Encoding.PEM


def _load_ca(root: Path) -> tuple[Any, Any]:
    x509, _, serialization, _, _, _ = _crypto()
    ca_dir = root / "ca"
    _check_private(ca_dir, "dir", 0o077)
    _check_private(ca_dir / "ca.key", "file", 0o077)
    _check_private(ca_dir / "ca.crt", "file", 0o022)
    cert = x509.load_pem_x509_certificate(_read(ca_dir / "ca.crt"))
    key = serialization.load_pem_private_key(_read(ca_dir / "ca.key"), password=None)
    return cert, key


def _subject_alt_names(name: str, hosts: list[str]) -> list[object]:
    x509, _, _, _, _, _ = _crypto()
    sans: list[object] = []
    seen: set[str] = set()
    for host in ([name] if _is_hostname(name) else []) + list(hosts):
        host = str(host).strip()
        if not host or host in seen:
            continue
        seen.add(host)
        try:
            sans.append(x509.IPAddress(ipaddress.ip_address(host)))
            continue
        except ValueError:
            pass
        if not _is_hostname(host):
            raise KeystoreError(f"host {host!r} is neither an IP address nor a valid DNS name")
        sans.append(x509.DNSName(host))
    return sans


def create_identity(keystore: str | os.PathLike[str], name: str, hosts: list[str] | tuple[str, ...] = (), days: int = IDENTITY_DAYS,
                    valid_from: datetime.datetime | None = None) -> tuple[Path, Path]:
    """Create identity ``name`` (a robot, a host or an operator) signed by the keystore's CA:
    ``(certificate path, key path)``. Its certificate's common name is ``name``, which the
    access rules match (``cert_common_names``). ``hosts``: extra DNS names and IP addresses it
    is reached at (subject alternative names). ``valid_from`` (default now) exists for tests of
    expired certificates. Refuses to replace an existing identity."""
    x509, hashes, _, _, ExtendedKeyUsageOID, NameOID = _crypto()
    check_name(name)
    if not isinstance(days, int) or isinstance(days, bool) or not 1 <= days <= MAX_DAYS:
        raise KeystoreError(f"identity validity must be 1..{MAX_DAYS} days, got {days!r}")
    root = _check_keystore(keystore)
    ca_cert, ca_key = _load_ca(root)
    sans = _subject_alt_names(name, list(hosts))
    ident_dir = root / "identities"
    _check_private(ident_dir, "dir", 0o077)
    start = (valid_from or _now()) - _CLOCK_SKEW
    end = start + _CLOCK_SKEW + datetime.timedelta(days=days)
    if end > ca_cert.not_valid_after_utc:
        end = ca_cert.not_valid_after_utc  # a certificate cannot outlive its CA
    key = _new_key()
    builder = (
        x509.CertificateBuilder()
        .subject_name(x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, name), x509.NameAttribute(NameOID.ORGANIZATION_NAME, "EMOS")]))
        .issuer_name(ca_cert.subject).public_key(key.public_key()).serial_number(x509.random_serial_number())
        .not_valid_before(start).not_valid_after(end)
        .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
        .add_extension(x509.KeyUsage(digital_signature=True, content_commitment=False, key_encipherment=False, data_encipherment=False,
                                     key_agreement=False, key_cert_sign=False, crl_sign=False, encipher_only=False, decipher_only=False), critical=True)
        .add_extension(x509.ExtendedKeyUsage([ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH]), critical=False)
        .add_extension(x509.SubjectKeyIdentifier.from_public_key(key.public_key()), critical=False)
        .add_extension(x509.AuthorityKeyIdentifier.from_issuer_public_key(ca_key.public_key()), critical=False)
    )
    if sans:
        builder = builder.add_extension(x509.SubjectAlternativeName(sans), critical=False)
    cert = builder.sign(ca_key, hashes.SHA256())
    folder = ident_dir / name
    _mkdir_private(folder)
    _write_private(folder / f"{name}.key", _key_pem(key))
    _write_private(folder / f"{name}.crt", cert.public_bytes(_pem()))
    return folder / f"{name}.crt", folder / f"{name}.key"


def identity_names(keystore: str | os.PathLike[str]) -> list[str]:
    root = _check_keystore(keystore)
    return sorted(p.name for p in (root / "identities").iterdir() if p.is_dir() and _NAME_RE.match(p.name))


def load_identity(keystore: str | os.PathLike[str], name: str, *, allow_expired: bool = False) -> tuple[Path, Path, Path]:
    """``(certificate path, private key path, CA certificate path)`` of identity ``name``, after
    checking: the keystore and the files are ours with private modes (the key 0600), the
    certificate names ``name``, was signed by this keystore's CA and is valid now (unless
    ``allow_expired``), and the key is the certificate's. Raises :class:`KeystoreError` naming
    the file and the problem otherwise."""
    x509, _, serialization, _, _, _ = _crypto()
    check_name(name)
    root = _check_keystore(keystore)
    ca_path = root / "ca" / "ca.crt"
    _check_private(ca_path, "file", 0o022)
    ca_cert = x509.load_pem_x509_certificate(_read(ca_path))
    folder = root / "identities" / name
    if not folder.exists():
        known = ", ".join(identity_names(root)) or "none"
        raise KeystoreError(f"keystore {root} has no identity {name!r} (identities: {known}); create it with "
                            f"`emos security create-identity {root} {name}`")
    _check_private(folder, "dir", 0o077)
    cert_path, key_path = folder / f"{name}.crt", folder / f"{name}.key"
    _check_private(cert_path, "file", 0o022)
    _check_private(key_path, "file", 0o077)
    try:
        cert = x509.load_pem_x509_certificate(_read(cert_path))
        key = serialization.load_pem_private_key(_read(key_path), password=None)
    except ValueError as exc:
        raise KeystoreError(f"identity {name!r} in {root}: cannot read its certificate or key: {exc}") from None
    try:
        cert.verify_directly_issued_by(ca_cert)
    except Exception as exc:  # noqa: BLE001 - ValueError, TypeError, InvalidSignature
        raise KeystoreError(f"{cert_path} was not signed by this keystore's CA ({ca_path}): {exc or type(exc).__name__}") from None
    cn = [a.value for a in cert.subject.get_attributes_for_oid(_crypto()[5].COMMON_NAME)]
    if cn != [name]:
        raise KeystoreError(f"{cert_path} names {cn!r}, expected the common name {name!r}")
    pub = serialization.PublicFormat.SubjectPublicKeyInfo
    if key.public_key().public_bytes(serialization.Encoding.DER, pub) != cert.public_key().public_bytes(serialization.Encoding.DER, pub):
        raise KeystoreError(f"{key_path} is not the private key of {cert_path}")
    now = _now()
    if not allow_expired and not cert.not_valid_before_utc <= now <= cert.not_valid_after_utc:
        raise KeystoreError(f"{cert_path} is valid from {cert.not_valid_before_utc:%Y-%m-%d %H:%M} to {cert.not_valid_after_utc:%Y-%m-%d %H:%M} UTC, "
                            f"not now: create a new identity")
    return cert_path, key_path, ca_path
