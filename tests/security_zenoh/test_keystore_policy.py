"""The keystore (CA, identities, modes, refusing to overwrite, what load_identity checks), the
access rules derived from a real recipe, and the check that a secure run's configuration is
secure. No processes, no sessions."""
import datetime
import json
import os
import stat

import pytest

from emos.security.keystore import KeystoreError, create_identity, create_keystore, load_identity
from emos.security.policy import Roles, derive_permissions, write_policies
from emos.security.recipe_graph import load_recipe_graph
from emos.security.watch import allowed_puts

pytestmark = pytest.mark.unit

zenoh = pytest.importorskip("zenoh", reason="the 'net' extra (eclipse-zenoh) is not installed")


def _mode(path):
    return stat.S_IMODE(os.lstat(path).st_mode)


@pytest.fixture(scope="module")
def keys(tmp_path_factory):
    ks = tmp_path_factory.mktemp("ks") / "keys"
    create_keystore(ks)
    create_identity(ks, "robot1", hosts=["robot1.local", "192.168.1.20"])
    create_identity(ks, "alice")
    create_identity(ks, "bob")
    return ks


def test_keystore_files_are_private_and_identities_verify(keys):
    from cryptography import x509

    assert _mode(keys) == 0o700 and _mode(keys / "ca") == 0o700 and _mode(keys / "identities" / "robot1") == 0o700
    for f in (keys / "ca" / "ca.key", keys / "ca" / "ca.crt", keys / "identities" / "robot1" / "robot1.key"):
        assert _mode(f) == 0o600, f
    cert_path, key_path, ca_path = load_identity(keys, "robot1")
    cert = x509.load_pem_x509_certificate(cert_path.read_bytes())
    ca = x509.load_pem_x509_certificate(ca_path.read_bytes())
    cert.verify_directly_issued_by(ca)
    sans = cert.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    assert "robot1.local" in sans.get_values_for_type(x509.DNSName) and "robot1" in sans.get_values_for_type(x509.DNSName)
    assert [str(a) for a in sans.get_values_for_type(x509.IPAddress)] == ["192.168.1.20"]
    assert ca.extensions.get_extension_for_class(x509.BasicConstraints).value.ca is True
    assert cert.extensions.get_extension_for_class(x509.BasicConstraints).value.ca is False
    days = (cert.not_valid_after_utc - cert.not_valid_before_utc).days
    assert 360 <= days <= 366


def test_nothing_is_overwritten(keys):
    with pytest.raises(KeystoreError, match="not empty"):
        create_keystore(keys)
    before = (keys / "identities" / "alice" / "alice.key").read_bytes()
    with pytest.raises(KeystoreError, match="already exists"):
        create_identity(keys, "alice")
    assert (keys / "identities" / "alice" / "alice.key").read_bytes() == before


@pytest.mark.parametrize("name", ["", "../x", "a/b", "-x", "x" * 64, "a b"])
def test_bad_identity_names_are_refused(keys, name):
    with pytest.raises(KeystoreError, match="identity name"):
        create_identity(keys, name)


def test_load_identity_refuses_what_it_should_not_use(keys, tmp_path):
    with pytest.raises(KeystoreError, match="no identity 'nobody'"):
        load_identity(keys, "nobody")
    past = datetime.datetime.now(datetime.UTC) - datetime.timedelta(days=30)
    create_identity(keys, "stale", valid_from=past, days=2)
    with pytest.raises(KeystoreError, match="not now"):
        load_identity(keys, "stale")
    assert load_identity(keys, "stale", allow_expired=True)[0].name == "stale.crt"
    key = keys / "identities" / "alice" / "alice.key"
    os.chmod(key, 0o644)
    try:
        with pytest.raises(KeystoreError, match="other users may read"):
            load_identity(keys, "alice")
    finally:
        os.chmod(key, 0o600)
    # a certificate of another CA planted under this keystore's name
    other = tmp_path / "other"
    create_keystore(other)
    create_identity(other, "mallory")
    mine = keys / "identities" / "mallory"
    mine.mkdir(mode=0o700)
    for suffix in (".crt", ".key"):
        data = (other / "identities" / "mallory" / f"mallory{suffix}").read_bytes()
        fd = os.open(mine / f"mallory{suffix}", os.O_WRONLY | os.O_CREAT, 0o600)
        os.write(fd, data)
        os.close(fd)
    with pytest.raises(KeystoreError, match="not signed by this keystore's CA"):
        load_identity(keys, "mallory")
    with pytest.raises(KeystoreError, match="does not exist"):
        load_identity(tmp_path / "nowhere", "alice")


@pytest.fixture(scope="module")
def graph():
    return load_recipe_graph("recipes/point_navigation.py")


def test_policy_of_a_real_recipe(graph, keys, tmp_path):
    """point_navigation: the DriveManager publishes /cmd_vel, the Localizer reads /initialpose
    that no component publishes: an operator may publish /initialpose, never /cmd_vel."""
    assert "/cmd_vel" in graph.outputs and "/initialpose" in graph.external_inputs and "/cmd_vel" not in graph.external_inputs
    assert "planner/plan_path" in graph.services
    roles = Roles(robots=["robot1"], operators=["alice"], viewers=["bob"])
    perms = derive_permissions(graph, roles)
    assert "/cmd_vel" in perms["robot1"]["publish"] and "/cmd_vel" not in perms["alice"]["publish"]
    assert "/initialpose" in perms["alice"]["publish"] and perms["bob"]["publish"] == [] and perms["bob"]["call"] == []
    assert "/odometry/localized" in perms["bob"]["subscribe"]
    files = write_policies(graph, roles, keys, "lab", tmp_path / "pol", listen=["tls/0.0.0.0:7447"], connect=["tls/robot1.local:7447"])
    assert sorted(p.name for p in files) == ["alice.json5", "bob.json5", "robot1.json5"]
    for p in files:
        assert _mode(p) == 0o600
        text = p.read_text()
        assert text.startswith("// Zenoh configuration of identity")  # commented, for hand edits
        conf = zenoh.Config.from_file(str(p))  # Zenoh 1.x accepts it as written
        tls = json.loads(conf.get_json("transport/link/tls"))
        assert tls["enable_mtls"] is True and tls["listen_certificate"].endswith(f"{p.stem}.crt")
        acl = json.loads(conf.get_json("access_control"))
        puts = allowed_puts(acl)
        assert "emos/lab/cmd_vel" in puts["robot1"] and "emos/lab/cmd_vel" not in puts["alice"] and not puts.get("bob")
        assert "emos/lab/initialpose" in puts["alice"]
    robot = zenoh.Config.from_file(str(tmp_path / "pol" / "robot1.json5"))
    assert json.loads(robot.get_json("listen/endpoints")) == ["tls/0.0.0.0:7447"]
    assert json.loads(robot.get_json("connect/endpoints")) == ["tls/robot1.local:7447", "tls/localhost:7447"]
    with pytest.raises(KeystoreError, match="already exists"):  # hand edits are kept
        write_policies(graph, roles, keys, "lab", tmp_path / "pol")
    with pytest.raises(KeystoreError, match="two roles"):
        Roles(robots=["robot1"], operators=["robot1"])
    with pytest.raises(KeystoreError, match="not a TLS endpoint"):
        write_policies(graph, roles, keys, "lab", tmp_path / "pol2", listen=["tcp/0.0.0.0:7447"])


def test_check_secure_refuses_plain_configurations(keys, graph, tmp_path, monkeypatch):
    from emos.security.secure_run import check_secure, secure_config_path
    from emos.transport.zenoh_config import load_config

    files = write_policies(graph, Roles(robots=["robot1"]), keys, "lab", tmp_path / "pol", listen=["tls/127.0.0.1:7447"])
    check_secure(zenoh.Config.from_file(str(files[0])), "robot1.json5")
    assert secure_config_path(keys, "x.py", None, files[0]) == files[0]
    plain = tmp_path / "plain.json5"
    plain.write_text(json.dumps({"mode": "peer", "listen": {"endpoints": ["tcp/0.0.0.0:7447"]}}))
    with pytest.raises(KeystoreError) as err:
        check_secure(zenoh.Config.from_file(str(plain)), "plain.json5")
    for what in ("enable_mtls", "protocols", "not TLS", "access_control.enabled", "multicast"):
        assert what in str(err.value)
    # a secure run refuses a plain file wherever it comes from ($EMOS_ZENOH_CONFIG, use_network)
    monkeypatch.setenv("EMOS_ZENOH_SECURE", "1")
    with pytest.raises(KeystoreError, match="not secure"):
        load_config(zenoh, str(plain))
    load_config(zenoh, str(files[0]))
    with pytest.raises(KeystoreError, match="no single robot policy"):
        secure_config_path(keys, "other_recipe.py", None)
