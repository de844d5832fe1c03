"""End-to-end signatures of the daemon's zenoh messages (Ed25519).

Every message the daemon publishes, and every reply of its queryable,
carries in its attachment (a JSON object) a ``signature`` made with the
daemon's Ed25519 key over the message's key expression, job id and payload.
A message is signed once, when it is first published; the journal keeps the
signed attachment and the queryable replies with it, so a payload changed
on disk afterwards (the journal, a finger.stl) fails verification too.
TLS protects one link; the signature protects the message across every
zenoh router between the print server and the cell, which the print server
may not control. A cell controller checks each message with
:func:`verify_message` and the daemon's public key (``signing.pub``).

What is signed (bytes, ``\\0``-separated; no field can hold a ``\\0``):
``fcsod-signature-v1``, the key expression, the job id, and the SHA-256 of
the payload (hex).
"""

from __future__ import annotations

import base64
import hashlib
import json
import os
from dataclasses import replace
from pathlib import Path

from cryptography.exceptions import InvalidSignature
from cryptography.hazmat.primitives import serialization
from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey, Ed25519PublicKey

from fcso.errors import ConfigError

from ..config import DaemonConfig
from .messages import BusMessage, MessageSignature, split_job_key

#: Domain separation: a signature made for anything else never verifies here.
SIGNATURE_CONTEXT = b"fcsod-signature-v1"

#: File names of the daemon's key pair in a state or PKI folder.
SIGNING_KEY_NAME = "signing.key"
VERIFY_KEY_NAME = "signing.pub"


class SignatureError(Exception):
    """A message that is unsigned, malformed or not signed by the expected key; the message says which."""


def signed_bytes(key_expr: str, job_id: str, payload: bytes) -> bytes:
    """The bytes a signature covers: context, key expression, job id and the payload's SHA-256 (hex)."""
    return b"\0".join(
        [SIGNATURE_CONTEXT, key_expr.encode(), job_id.encode(), hashlib.sha256(payload).hexdigest().encode()]
    )


def key_id(public_key: Ed25519PublicKey) -> str:
    """First 16 hex digits of the SHA-256 of the raw public key: names the key in attachments and logs."""
    raw = public_key.public_bytes(serialization.Encoding.Raw, serialization.PublicFormat.Raw)
    return hashlib.sha256(raw).hexdigest()[:16]


def job_id_of(key_expr: str) -> str | None:
    """The job id chunk of ``<prefix>/<cell>/jobs/<job_id>/<topic>`` (:func:`fcsod.bus.messages.split_job_key`), None
    for other keys.
    """
    split = split_job_key(key_expr)
    return split[0] if split is not None else None


class Signer:
    """Signs the daemon's messages.

    Parameters
    ----------
    private_key : Ed25519PrivateKey
    """

    def __init__(self, private_key: Ed25519PrivateKey):
        self.private_key = private_key
        self.public_key = private_key.public_key()
        self.key_id = key_id(self.public_key)

    @classmethod
    def from_file(cls, path: str | Path) -> Signer:
        """Load a PEM (PKCS#8) Ed25519 private key.

        Raises
        ------
        ConfigError
            Missing or unreadable file, or not an Ed25519 private key.
        """
        return cls(_load_private_key(Path(path)))

    def sign(self, message: BusMessage) -> BusMessage:
        """``message`` with its signed attachment (see :meth:`attachment`)."""
        return replace(
            message, attachment=self.attachment(message.key_expr, message.job_id, message.payload, message.attachment)
        )

    def attachment(self, key_expr: str, job_id: str, payload: bytes, attachment: bytes | None) -> bytes:
        """The attachment to send: ``attachment``'s JSON object (or ``{"job_id": ...}``) plus ``signature``.

        Parameters
        ----------
        key_expr : str
            Full key expression of the message.
        job_id : str
        payload : bytes
        attachment : bytes or None
            The message's own attachment, a JSON object (the design's), if any.
        """
        body = json.loads(attachment) if attachment else {"job_id": job_id}
        signature = self.private_key.sign(signed_bytes(key_expr, job_id, payload))
        body["signature"] = MessageSignature(
            key_id=self.key_id, signature_base64=base64.b64encode(signature).decode()
        ).model_dump()
        return json.dumps(body, separators=(",", ":")).encode()


def verify_message(key_expr: str, payload: bytes, attachment: bytes | None, public_key: Ed25519PublicKey) -> dict:
    """Check that a message comes from the daemon holding ``public_key``'s private key.

    Parameters
    ----------
    key_expr : str
        The sample's key expression, ``<prefix>/<cell>/jobs/<job_id>/<topic>``.
    payload : bytes
        The sample's payload.
    attachment : bytes or None
        The sample's attachment (JSON with ``job_id`` and ``signature``).
    public_key : Ed25519PublicKey
        The daemon's public key (:func:`load_verify_key` reads ``signing.pub``).

    Returns
    -------
    dict
        The attachment, verified (its ``job_id`` is the key's).

    Raises
    ------
    SignatureError
        No attachment, no signature, a job id that is not the key's, a
        signature by another key, or a key, job id or payload changed after
        signing.
    """
    if not attachment:
        raise SignatureError(f"{key_expr}: unsigned message (no attachment)")
    try:
        body = json.loads(attachment)
        signature = MessageSignature.model_validate(body["signature"])
        raw = base64.b64decode(signature.signature_base64, validate=True)
    except (ValueError, TypeError, KeyError) as exc:
        raise SignatureError(f"{key_expr}: unsigned or malformed signature ({type(exc).__name__}: {exc})") from None
    job_id = body.get("job_id")
    if not isinstance(job_id, str) or job_id != job_id_of(key_expr):
        raise SignatureError(f"{key_expr}: attachment job_id {job_id!r} is not the key's job id")
    expected = key_id(public_key)
    if signature.key_id != expected:
        raise SignatureError(f"{key_expr}: signed by key {signature.key_id}, not the daemon's key {expected}")
    try:
        public_key.verify(raw, signed_bytes(key_expr, job_id, payload))
    except InvalidSignature:
        raise SignatureError(
            f"{key_expr}: bad signature (key, job id or payload changed after signing, or a forged key id)"
        ) from None
    return body


def generate_signing_key(path: str | Path) -> Signer:
    """Create an Ed25519 key pair: ``path`` (private, PEM PKCS#8, mode 0600) and ``path`` with ``.pub`` (public, PEM).

    Returns
    -------
    Signer
    """
    path = Path(path)
    private_key = Ed25519PrivateKey.generate()
    pem = private_key.private_bytes(
        serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8, serialization.NoEncryption()
    )
    write_private(path, pem)
    write_public_key(private_key.public_key(), path.with_name(VERIFY_KEY_NAME))
    return Signer(private_key)


def write_public_key(public_key: Ed25519PublicKey, path: Path) -> None:
    """Write a public key as PEM (SubjectPublicKeyInfo), mode 0644."""
    path.write_bytes(
        public_key.public_bytes(serialization.Encoding.PEM, serialization.PublicFormat.SubjectPublicKeyInfo)
    )
    path.chmod(0o644)


def write_private(path: Path, data: bytes) -> None:
    """Write secret bytes to a new file created with mode 0600 (never readable by others, even for an instant)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.unlink(missing_ok=True)
    descriptor = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    with os.fdopen(descriptor, "wb") as stream:
        stream.write(data)


def load_verify_key(path: str | Path) -> Ed25519PublicKey:
    """Read the daemon's public key (PEM) from ``signing.pub``.

    Raises
    ------
    ConfigError
        Missing file or not an Ed25519 public key.
    """
    path = Path(path)
    try:
        key = serialization.load_pem_public_key(path.read_bytes())
    except OSError as exc:
        raise ConfigError(path, f"cannot read the daemon's public key: {exc.strerror}") from None
    except ValueError:
        raise ConfigError(path, "not a PEM public key") from None
    if not isinstance(key, Ed25519PublicKey):
        raise ConfigError(path, "not an Ed25519 public key")
    return key


def _load_private_key(path: Path) -> Ed25519PrivateKey:
    try:
        key = serialization.load_pem_private_key(path.read_bytes(), password=None)
    except OSError as exc:
        raise ConfigError(path, f"cannot read the signing key: {exc.strerror}") from None
    except (ValueError, TypeError):
        raise ConfigError(path, "not an unencrypted PEM private key") from None
    if not isinstance(key, Ed25519PrivateKey):
        raise ConfigError(path, "not an Ed25519 private key")
    return key


def signing_key_path(config: DaemonConfig) -> Path:
    """Where the daemon's signing key is: ``[bus] signing_key`` or ``<state.dir>/signing.key``."""
    return config.bus.signing_key or config.state.dir / SIGNING_KEY_NAME


def verify_key_path(config: DaemonConfig) -> Path:
    """Where the daemon's public key is: ``[bus] verify_key`` or ``signing.pub`` next to the signing key."""
    return config.bus.verify_key or signing_key_path(config).with_name(VERIFY_KEY_NAME)


def daemon_signer(config: DaemonConfig) -> tuple[Signer, bool]:
    """The daemon's signer, and whether its key was created now (only the default key in the state folder is created).

    Raises
    ------
    ConfigError
        A configured ``[bus] signing_key`` that is missing or not an Ed25519 key.
    """
    path = signing_key_path(config)
    if config.bus.signing_key is None and not path.exists():
        path.parent.mkdir(parents=True, exist_ok=True)
        return generate_signing_key(path), True
    return Signer.from_file(path), False
