"""fcsod pki init: the files it writes, their modes, the certificate chain, and the deploy template."""

from __future__ import annotations

import json
import stat
import tomllib
from pathlib import Path

import pytest
import zenoh
from cryptography import x509
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.x509.oid import NameOID

from fcso.errors import ConfigError
from fcsod.bus.pki import access_control, daemon_zenoh_config, init_pki, link_weaknesses
from fcsod.cli import main

REPO = Path(__file__).resolve().parents[2]


def _mode(path: Path) -> int:
    return stat.S_IMODE(path.stat().st_mode)


def _cert(path: Path) -> x509.Certificate:
    return x509.load_pem_x509_certificate(path.read_bytes())


def test_pki_init_writes_keys_0600_and_a_chain_to_its_ca(tmp_path, capsys):
    directory = tmp_path / "pki"
    assert (
        main(
            [
                "pki",
                "init",
                str(directory),
                "--cell",
                "c7",
                "--client",
                "robot-a",
                "--client",
                "robot-b",
                "--host",
                "printer.lan",
                "--port",
                "7500",
            ]
        )
        == 0
    )
    printed = capsys.readouterr().out
    assert f'config_file = "{directory / "daemon" / "zenoh.json5"}"' in printed
    assert "LoadCredential=key.pem:" in printed and "--zenoh-config" in printed

    secrets = [directory / "ca" / "ca.key", directory / "daemon" / "key.pem", directory / "daemon" / "signing.key"]
    secrets += [directory / "clients" / name / "key.pem" for name in ("robot-a", "robot-b")]
    for path in secrets:
        assert _mode(path) == 0o600, path
    for folder in (directory, directory / "ca", directory / "daemon", directory / "clients" / "robot-a"):
        assert _mode(folder) == 0o700, folder

    ca = _cert(directory / "ca" / "ca.pem")
    assert ca.extensions.get_extension_for_class(x509.BasicConstraints).value.ca
    for path, name in [
        (directory / "daemon" / "cert.pem", "fcsod-c7"),
        (directory / "clients" / "robot-a" / "cert.pem", "robot-a"),
    ]:
        leaf = _cert(path)
        leaf.verify_directly_issued_by(ca)
        assert leaf.subject.get_attributes_for_oid(NameOID.COMMON_NAME)[0].value == name
        assert not leaf.extensions.get_extension_for_class(x509.BasicConstraints).value.ca
    daemon_names = (
        _cert(directory / "daemon" / "cert.pem").extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    )
    assert daemon_names.get_values_for_type(x509.DNSName) == ["printer.lan"]
    assert isinstance(_cert(directory / "clients" / "robot-b" / "cert.pem").public_key(), ec.EllipticCurvePublicKey)

    daemon = zenoh.Config.from_file(str(directory / "daemon" / "zenoh.json5"))
    assert json.loads(daemon.get_json("listen/endpoints")) == ["tls/0.0.0.0:7500"]
    assert json.loads(daemon.get_json("transport/link/tls/enable_mtls")) is True
    acl = json.loads(daemon.get_json("access_control"))
    assert acl["default_permission"] == "deny" and acl["subjects"][0]["cert_common_names"] == ["robot-a", "robot-b"]
    assert link_weaknesses(daemon) == []
    client = zenoh.Config.from_file(str(directory / "clients" / "robot-a" / "zenoh.json5"))
    assert json.loads(client.get_json("connect/endpoints")) == ["tls/printer.lan:7500"]
    assert json.loads(client.get_json("mode")) == "client"
    assert (directory / "clients" / "robot-a" / "signing.pub").read_bytes() == (
        directory / "daemon" / "signing.pub"
    ).read_bytes()


@pytest.mark.parametrize(
    "ros2_args, ros2_keys", [([], []), (["--ros2-domain-id", "3"], ["3/**", "3/**/@adv/**", "@ros2_lv/3/**"])]
)
def test_pki_init_lets_the_ros2_key_expressions_through_only_when_asked(tmp_path, capsys, ros2_args, ros2_keys):
    directory = tmp_path / "pki"
    assert (
        main(["pki", "init", str(directory), "--cell", "c7", "--client", "robot-a", "--host", "localhost", *ros2_args])
        == 0
    )
    acl = json.loads(zenoh.Config.from_file(str(directory / "daemon" / "zenoh.json5")).get_json("access_control"))
    assert [rule["key_exprs"] for rule in acl["rules"]] == [["fcso/c7/**", *ros2_keys]] * 2


def test_pki_init_refuses_a_folder_with_a_ca(tmp_path):
    init_pki(tmp_path, "c1", ["a"], hosts=["localhost"])
    with pytest.raises(ConfigError, match="already holds a CA"):
        init_pki(tmp_path, "c1", ["b"], hosts=["localhost"])
    assert main(["pki", "init", str(tmp_path), "--cell", "c1", "--client", "b"]) == 2


def test_deploy_zenoh_config_is_the_secure_default():
    """deploy/zenoh.json5 is what fcsod pki init writes for cell1, one controller and the systemd credentials folder."""
    deployed = zenoh.Config.from_file(str(REPO / "deploy" / "zenoh.json5"))
    expected = daemon_zenoh_config(
        ["tls/0.0.0.0:7447"],
        Path("/run/credentials/fcsod.service"),
        access_control("fcso", "cell1", ["cell1-controller"]),
    )
    for key in (
        "mode",
        "listen/endpoints",
        "transport/link/protocols",
        "transport/link/tls/enable_mtls",
        "transport/link/tls/listen_private_key",
        "access_control/rules",
        "access_control/default_permission",
    ):
        value = json.loads(deployed.get_json(key))
        want = expected
        for part in key.split("/"):
            want = want[part]
        assert value == want, key
    assert link_weaknesses(deployed) == []


def test_plain_tcp_is_named_as_a_weakness():
    config = zenoh.Config()
    config.insert_json5("listen/endpoints", '["tcp/0.0.0.0:7447"]')
    weaknesses = link_weaknesses(config)
    assert any("tcp/0.0.0.0:7447" in w and "without TLS" in w for w in weaknesses)
    assert any("access control is off" in w for w in weaknesses)


def test_systemd_unit_loads_every_key_the_configs_name_as_a_credential():
    """Every file below /run/credentials/fcsod.service in zenoh.json5 and fcsod.toml comes from a LoadCredential=
    line.
    """
    unit = (REPO / "deploy" / "fcsod.service").read_text()
    loaded = {
        line.split("=", 1)[1].split(":", 1)[0] for line in unit.splitlines() if line.startswith("LoadCredential=")
    }
    credentials = "/run/credentials/fcsod.service/"
    deployed = zenoh.Config.from_file(str(REPO / "deploy" / "zenoh.json5"))
    tls = json.loads(deployed.get_json("transport/link/tls"))
    named = {v.removeprefix(credentials) for v in tls.values() if isinstance(v, str) and v.startswith(credentials)}
    daemon = tomllib.loads((REPO / "deploy" / "fcsod.toml").read_text())
    named.add(daemon["bus"]["signing_key"].removeprefix(credentials))
    assert named == {"ca.pem", "cert.pem", "key.pem", "signing.key"}
    assert named == loaded
    assert "RestartPreventExitStatus=2" in unit


def test_pki_add_client_issues_from_the_same_ca_without_touching_the_access_control(tmp_path, capsys):
    init_pki(tmp_path, "c1", ["a"], hosts=["localhost"])
    acl_before = (tmp_path / "daemon" / "zenoh.json5").read_text()
    assert (
        main(
            ["pki", "add-client", str(tmp_path), "plant-router", "--connect", "tls/printer:7447", "--host", "10.0.0.5"]
        )
        == 0
    )
    assert "cert_common_names" in capsys.readouterr().out
    leaf = _cert(tmp_path / "clients" / "plant-router" / "cert.pem")
    leaf.verify_directly_issued_by(_cert(tmp_path / "ca" / "ca.pem"))
    names = leaf.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    assert [str(ip) for ip in names.get_values_for_type(x509.IPAddress)] == ["10.0.0.5"]
    assert _mode(tmp_path / "clients" / "plant-router" / "key.pem") == 0o600
    assert (tmp_path / "daemon" / "zenoh.json5").read_text() == acl_before
    assert main(["pki", "add-client", str(tmp_path / "nothing"), "x", "--connect", "tls/printer:7447"]) == 2
