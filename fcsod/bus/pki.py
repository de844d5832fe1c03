"""``fcsod pki init``: a small local CA, the daemon's and the cell controllers' certificates, zenoh configs with mTLS
and access control.

Layout written below ``DIR`` (private keys mode 0600 in 0700 folders)::

    ca/ca.pem, ca/ca.key                  the CA (keep ca.key offline once clients are issued)
    daemon/ca.pem, cert.pem, key.pem      the daemon's TLS identity (CN fcsod-<cell>)
    daemon/signing.key, signing.pub       the daemon's Ed25519 message-signing key pair
    daemon/zenoh.json5                    the daemon's zenoh session: tls listen, mTLS, access control
    clients/<name>/ca.pem, cert.pem, key.pem, signing.pub, zenoh.json5
                                          one cell controller: client mode, mTLS, the daemon's public key

Certificates use ECDSA P-256 keys (what rustls, zenoh's TLS, accepts
everywhere) and SHA-256 signatures.
"""

from __future__ import annotations

import datetime
import ipaddress
import json
import socket
from dataclasses import dataclass
from pathlib import Path

from cryptography import x509
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

from fcso.errors import ConfigError

from ..config import LIVELINESS_ADMIN_SPACE
from .signing import SIGNING_KEY_NAME, VERIFY_KEY_NAME, generate_signing_key, write_private

#: Certificate lifetimes, days.
CA_DAYS = 3650
LEAF_DAYS = 825

#: zenoh messages a named client may send to the daemon (ingress on the daemon's session).
CLIENT_INGRESS = ["declare_subscriber", "query", "declare_liveliness_subscriber", "liveliness_query"]
#: zenoh messages the daemon's session may send to a named client (egress); a zenoh router between the
#: daemon and the controllers routes queries only to queryables declared to it, hence declare_queryable.
DAEMON_EGRESS = ["put", "reply", "declare_queryable", "liveliness_token"]

_HEADER = "// {what}\n// Written by `fcsod pki init`; zenoh 1.x configuration (JSON5, plain JSON here).\n"


@dataclass
class PkiFiles:
    """What :func:`init_pki` wrote."""

    directory: Path
    daemon_zenoh_config: Path
    signing_key: Path
    verify_key: Path
    clients: dict[str, Path]
    runtime_dir: Path


def _name(common_name: str) -> x509.Name:
    return x509.Name(
        [x509.NameAttribute(NameOID.ORGANIZATION_NAME, "fcsod"), x509.NameAttribute(NameOID.COMMON_NAME, common_name)]
    )


def _write_key(key: ec.EllipticCurvePrivateKey, path: Path) -> None:
    pem = key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8, serialization.NoEncryption())
    write_private(path, pem)


def _write_cert(certificate: x509.Certificate, path: Path) -> None:
    path.write_bytes(certificate.public_bytes(serialization.Encoding.PEM))
    path.chmod(0o644)


def _private_dir(path: Path) -> Path:
    path.mkdir(parents=True, exist_ok=True)
    path.chmod(0o700)
    return path


def create_ca(common_name: str) -> tuple[x509.Certificate, ec.EllipticCurvePrivateKey]:
    """A self-signed CA certificate (may sign leaf certificates only) and its key."""
    key = ec.generate_private_key(ec.SECP256R1())
    now = datetime.datetime.now(datetime.UTC)
    certificate = (
        x509.CertificateBuilder()
        .subject_name(_name(common_name))
        .issuer_name(_name(common_name))
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - datetime.timedelta(minutes=5))
        .not_valid_after(now + datetime.timedelta(days=CA_DAYS))
        .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
        .add_extension(
            x509.KeyUsage(
                False,
                False,
                False,
                False,
                False,
                key_cert_sign=True,
                crl_sign=True,
                encipher_only=False,
                decipher_only=False,
            ),
            critical=True,
        )
        .add_extension(x509.SubjectKeyIdentifier.from_public_key(key.public_key()), critical=False)
        .sign(key, hashes.SHA256())
    )
    return certificate, key


def issue(
    ca: x509.Certificate, ca_key: ec.EllipticCurvePrivateKey, common_name: str, hosts: list[str]
) -> tuple[x509.Certificate, ec.EllipticCurvePrivateKey]:
    """A leaf certificate for TLS server and client use, signed by ``ca``.

    Parameters
    ----------
    ca, ca_key
        The issuing CA.
    common_name : str
        The subject's CN: what the daemon's access control matches (``cert_common_names``).
    hosts : list of str
        DNS names and IP addresses the subject is reached at (subject alternative names; a
        client checks the daemon's against the host it connects to).
    """
    key = ec.generate_private_key(ec.SECP256R1())
    now = datetime.datetime.now(datetime.UTC)
    names: list[x509.GeneralName] = []
    for host in dict.fromkeys(hosts or [common_name]):
        try:
            names.append(x509.IPAddress(ipaddress.ip_address(host)))
        except ValueError:
            names.append(x509.DNSName(host))
    certificate = (
        x509.CertificateBuilder()
        .subject_name(_name(common_name))
        .issuer_name(ca.subject)
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - datetime.timedelta(minutes=5))
        .not_valid_after(now + datetime.timedelta(days=LEAF_DAYS))
        .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
        .add_extension(
            x509.KeyUsage(True, False, False, False, False, False, False, encipher_only=False, decipher_only=False),
            critical=True,
        )
        .add_extension(
            x509.ExtendedKeyUsage([ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH]), critical=False
        )
        .add_extension(x509.SubjectAlternativeName(names), critical=False)
        .add_extension(x509.AuthorityKeyIdentifier.from_issuer_public_key(ca_key.public_key()), critical=False)
        .sign(ca_key, hashes.SHA256())
    )
    return certificate, key


def access_control(prefix: str, cell: str, clients: list[str], ros2_domain_id: int | None = None) -> dict:
    """The daemon's zenoh ``access_control``: default deny; the named clients may subscribe, query and watch liveliness.

    Only the daemon publishes and answers under ``<prefix>/<cell>/**`` (egress
    to the clients); what a client sends is limited to subscriptions, queries
    and liveliness interest (ingress), so a client's ``put``, its queryable
    or its liveliness token under the daemon's keys never passes the daemon.

    Parameters
    ----------
    prefix, cell : str
        The ``[bus]`` keys.
    clients : list of str
        Common names of the client certificates allowed in.
    ros2_domain_id : int, optional
        The ``[ros2] domain_id`` when ``[ros2]`` is enabled: the same rules
        then cover the daemon's ROS 2 data, ``<domain_id>/**`` (with the
        AdvancedPublisher's cache, heartbeat and detection token under
        ``<domain_id>/**/@adv/**``), and its rmw_zenoh liveliness tokens,
        ``@ros2_lv/<domain_id>/**``.
    """
    # ** also matches the liveliness token's key, <prefix>/<cell>/daemon
    keys = [f"{prefix}/{cell}/**"]
    if ros2_domain_id is not None:
        # ** never matches a verbatim chunk such as @adv: the AdvancedPublisher's cache,
        # heartbeat and detection token (<topic key>/@adv/pub/...) need their own key
        keys += [
            f"{ros2_domain_id}/**",
            f"{ros2_domain_id}/**/@adv/**",
            f"{LIVELINESS_ADMIN_SPACE}/{ros2_domain_id}/**",
        ]
    return {
        "enabled": True,
        "default_permission": "deny",
        "rules": [
            {
                "id": "clients-ask",
                "messages": CLIENT_INGRESS,
                "flows": ["ingress"],
                "permission": "allow",
                "key_exprs": keys,
            },
            {
                "id": "daemon-tells",
                "messages": DAEMON_EGRESS,
                "flows": ["egress"],
                "permission": "allow",
                "key_exprs": keys,
            },
        ],
        "subjects": [{"id": "cell-controllers", "cert_common_names": list(clients)}],
        "policies": [
            {"id": "cell-controllers", "rules": ["clients-ask", "daemon-tells"], "subjects": ["cell-controllers"]}
        ],
    }


def daemon_zenoh_config(listen: list[str], key_dir: Path, acl: dict | None) -> dict:
    """The daemon's zenoh session: a peer listening on TLS endpoints, client certificates required, access control.

    ``key_dir`` is where the daemon reads ``ca.pem``, ``cert.pem`` and ``key.pem`` at run time.
    """
    tls = {
        "root_ca_certificate": str(key_dir / "ca.pem"),
        "listen_certificate": str(key_dir / "cert.pem"),
        "listen_private_key": str(key_dir / "key.pem"),
        **_tls_connect(key_dir),
        "close_link_on_expiration": True,
    }
    config: dict = _tls_session("peer", listen=listen, connect=[], tls=tls)
    if acl is not None:
        config["access_control"] = acl
    return config


def client_zenoh_config(connect: list[str], key_dir: Path) -> dict:
    """A cell controller's zenoh session: client mode, connecting over TLS with its certificate."""
    return _tls_session(
        "client",
        listen=[],
        connect=connect,
        tls={"root_ca_certificate": str(key_dir / "ca.pem"), **_tls_connect(key_dir)},
    )


def _tls_connect(key_dir: Path) -> dict:
    """The certificate a session presents when it connects, with mutual TLS and the peer's name checked."""
    return {
        "connect_certificate": str(key_dir / "cert.pem"),
        "connect_private_key": str(key_dir / "key.pem"),
        "enable_mtls": True,
        "verify_name_on_connect": True,
    }


def _tls_session(mode: str, listen: list[str], connect: list[str], tls: dict) -> dict:
    """A zenoh session config on TLS links only, scouting off."""
    return {
        "mode": mode,
        "listen": {"endpoints": listen},
        "connect": {"endpoints": connect},
        "scouting": {"multicast": {"enabled": False}, "gossip": {"enabled": False}},
        "transport": {"link": {"protocols": ["tls"], "tls": tls}},
    }


def write_json5(path: Path, what: str, config: dict) -> None:
    """Write a zenoh config (JSON is JSON5) with a comment line saying what it is."""
    path.write_text(_HEADER.format(what=what) + json.dumps(config, indent=2) + "\n", encoding="utf-8")


def _load_ca(directory: Path) -> tuple[x509.Certificate, ec.EllipticCurvePrivateKey]:
    ca_dir = directory / "ca"
    try:
        certificate = x509.load_pem_x509_certificate((ca_dir / "ca.pem").read_bytes())
        key = serialization.load_pem_private_key((ca_dir / "ca.key").read_bytes(), password=None)
    except OSError as exc:
        raise ConfigError(ca_dir, f"no CA here ({exc.strerror}): run fcsod pki init first") from None
    return certificate, key


def add_client(directory: str | Path, name: str, connect: list[str], hosts: list[str] | None = None) -> Path:
    """Issue a client certificate from the CA in ``directory`` and write the client's folder.

    The client is not added to the daemon's access control: only the names
    given to :func:`init_pki` are (add its name to the ``cert_common_names``
    in ``daemon/zenoh.json5``).

    Parameters
    ----------
    directory : path
        A folder made by :func:`init_pki`.
    name : str
        The client's common name.
    connect : list of str
        The daemon's endpoints as the client reaches them, e.g. ``tls/printserver:7447``.
    hosts : list of str, optional
        Names and addresses the subject is reached at, for a zenoh router the
        daemon connects to (its certificate's subject alternative names); default ``[name]``.

    Returns
    -------
    Path
        ``clients/<name>/``.
    """
    directory = Path(directory)
    ca, ca_key = _load_ca(directory)
    folder = _private_dir(directory / "clients" / name)
    certificate, key = issue(ca, ca_key, name, hosts or [name])
    _write_cert(ca, folder / "ca.pem")
    _write_cert(certificate, folder / "cert.pem")
    _write_key(key, folder / "key.pem")
    verify_key = directory / "daemon" / VERIFY_KEY_NAME
    if verify_key.is_file():
        (folder / VERIFY_KEY_NAME).write_bytes(verify_key.read_bytes())
    write_json5(
        folder / "zenoh.json5",
        f"zenoh session of cell controller {name!r}",
        client_zenoh_config(connect, folder.resolve()),
    )
    return folder


def default_hosts() -> list[str]:
    """This machine's names and loopback addresses: the daemon certificate's default subject alternative names."""
    names = [socket.gethostname(), socket.getfqdn(), "localhost", "127.0.0.1", "::1"]
    return list(dict.fromkeys(n for n in names if n))


def init_pki(
    directory: str | Path,
    cell: str,
    clients: list[str],
    prefix: str = "fcso",
    hosts: list[str] | None = None,
    port: int = 7447,
    runtime_dir: str | Path | None = None,
    acl: bool = True,
    ros2_domain_id: int | None = None,
) -> PkiFiles:
    """Create the CA, the daemon's and each client's certificate and keys, and their zenoh configs.

    Parameters
    ----------
    directory : path
        Where to write (created; refuses a folder that already holds a CA).
    cell : str
        The ``[bus] cell``; the daemon's certificate is ``fcsod-<cell>``.
    clients : list of str
        Common names of the cell controllers; each gets a certificate and is
        allowed in by the access control.
    prefix : str
        The ``[bus] prefix``.
    hosts : list of str, optional
        Names and addresses clients use to reach the daemon (default: this
        machine's names and loopback); the first is put in client configs.
    port : int
        TLS port of the daemon.
    runtime_dir : path, optional
        Where the daemon reads its keys when it runs (e.g.
        ``/run/credentials/fcsod.service`` with systemd's ``LoadCredential=``);
        default ``directory/daemon``.
    acl : bool
        Put access control into the daemon's config (off only to test what the signatures alone stop).
    ros2_domain_id : int, optional
        The ``[ros2] domain_id`` when the daemon runs with ``[ros2]`` enabled:
        the access control then lets its ROS 2 topics and liveliness tokens through.

    Raises
    ------
    ConfigError
        The folder already holds a CA, or a client name is not a plain name.
    """
    directory = Path(directory)
    if (directory / "ca" / "ca.key").exists():
        raise ConfigError(directory, "already holds a CA (ca/ca.key): choose an empty folder")
    for name in clients:
        if not name or any(c in name for c in "/\\\0 ") or name.startswith("."):
            raise ConfigError(directory, f"client name {name!r}: use letters, digits, '-', '_' or '.'")
    hosts = hosts or default_hosts()
    _private_dir(directory)
    ca_dir, daemon_dir = _private_dir(directory / "ca"), _private_dir(directory / "daemon")
    ca, ca_key = create_ca(f"fcsod CA {cell}")
    _write_cert(ca, ca_dir / "ca.pem")
    _write_key(ca_key, ca_dir / "ca.key")
    certificate, key = issue(ca, ca_key, f"fcsod-{cell}", hosts)
    _write_cert(ca, daemon_dir / "ca.pem")
    _write_cert(certificate, daemon_dir / "cert.pem")
    _write_key(key, daemon_dir / "key.pem")
    generate_signing_key(daemon_dir / SIGNING_KEY_NAME)
    key_dir = Path(runtime_dir) if runtime_dir is not None else daemon_dir.resolve()
    listen = [f"tls/0.0.0.0:{port}"]
    write_json5(
        daemon_dir / "zenoh.json5",
        f"zenoh session of the fcsod daemon of cell {cell!r}: TLS with client certificates, access control",
        daemon_zenoh_config(listen, key_dir, access_control(prefix, cell, clients, ros2_domain_id) if acl else None),
    )
    host = hosts[0]
    connect = [f"tls/{f'[{host}]' if ':' in host else host}:{port}"]
    written = {name: add_client(directory, name, connect) for name in clients}
    return PkiFiles(
        directory,
        daemon_dir / "zenoh.json5",
        daemon_dir / SIGNING_KEY_NAME,
        daemon_dir / VERIFY_KEY_NAME,
        written,
        key_dir,
    )


def config_lines(files: PkiFiles) -> list[str]:
    """What to put where, as printed by ``fcsod pki init``."""
    daemon = files.directory / "daemon"
    lines = [
        f"PKI written to {files.directory} (private keys 0600; keep ca/ca.key offline)",
        "",
        "fcsod.toml of the daemon:",
        "  [zenoh]",
        f'  config_file = "{files.daemon_zenoh_config.resolve()}"',
        "  [bus]",
        f'  signing_key = "{files.runtime_dir / SIGNING_KEY_NAME}"',
        "",
        f"the daemon reads ca.pem, cert.pem, key.pem and {SIGNING_KEY_NAME} from {files.runtime_dir}; with systemd:",
    ]
    lines += [
        f"  LoadCredential={name}:{(daemon / name).resolve()}"
        for name in ("ca.pem", "cert.pem", "key.pem", SIGNING_KEY_NAME)
    ]
    lines.append("")
    for name, folder in files.clients.items():
        folder = folder.resolve()
        lines += [
            f"cell controller {name!r}: copy {folder} to it, then",
            f"  fcsod subscribe --config fcsod.toml --zenoh-config {folder / 'zenoh.json5'} --verify-key "
            f"{folder / VERIFY_KEY_NAME}",
            f"  (python: fcsod.verify_message(key, payload, attachment, "
            f"fcsod.load_verify_key('{folder / VERIFY_KEY_NAME}')))",
        ]
    return lines


def _endpoints(config, kind: str) -> list[str]:
    """A zenoh config's ``listen`` or ``connect`` endpoints for its mode (they may be given per mode)."""
    value = json.loads(config.get_json(f"{kind}/endpoints"))
    if isinstance(value, dict):
        mode = json.loads(config.get_json("mode")) or "peer"
        value = value.get(mode, [])
    return list(value or [])


def link_weaknesses(config) -> list[str]:
    """What makes a zenoh session readable or writable by anyone on the network; empty for the secure set-up.

    Parameters
    ----------
    config : zenoh.Config
        The session's configuration.

    Returns
    -------
    list of str
        One sentence per weakness: endpoints without TLS, TLS without client
        certificates, access control off.
    """
    weaknesses = []
    endpoints = _endpoints(config, "listen") + _endpoints(config, "connect")
    plain = [e for e in endpoints if e.split("/", 1)[0] not in ("tls", "quic")]
    if plain:
        weaknesses.append(
            f"zenoh endpoints without TLS ({', '.join(plain)}): anyone who reaches them can read every design and "
            f"publish "
            "under the daemon's keys; use them in a lab only (fcsod pki init makes the secure set-up)"
        )
    if len(plain) < len(endpoints) and json.loads(config.get_json("transport/link/tls/enable_mtls")) is not True:
        weaknesses.append(
            "zenoh TLS without client certificates (transport/link/tls/enable_mtls is not true): any client may connect"
        )
    if json.loads(config.get_json("access_control/enabled")) is not True:
        weaknesses.append("zenoh access control is off: every connected client may publish under the daemon's keys")
    return weaknesses
