"""Security beyond one host: a keystore (a CA and the identities it signs), Zenoh access rules
and TLS configuration derived from a recipe, secure runs (``emos security``, ``emos run
--secure``; docs/network.md, "Security").

Recipe side::

    from emos.security import use_secure
    use_secure("~/emos-keys", identity="robot1")   # before launcher.bringup()

Other parts (the web UI's HTTPS) take a certificate with :func:`load_identity`.
"""
from __future__ import annotations

from emos.security.keystore import KeystoreError, create_identity, create_keystore, load_identity
from emos.security.secure_run import check_secure, secure_config_path, use_secure

__all__ = ["KeystoreError", "create_keystore", "create_identity", "load_identity", "use_secure", "check_secure", "secure_config_path"]
