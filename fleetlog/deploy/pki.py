"""A fleet's certificates, made with the ``cryptography`` library (no shell scripts).

One CA per fleet signs every certificate. Each certificate's common name is a fleetlog
identity (``fleetlog:vehicle:alpha``, :mod:`fleetlog.wire.access`), the only thing access
control matches on; routers' certificates also name the host names and addresses they are
reached at, because a client checks the name it dialled against them. Keys are ECDSA P-256
(fast on a vehicle's ARM computer, understood by rustls).
"""

from __future__ import annotations

import datetime as dt
import ipaddress
from dataclasses import dataclass

from cryptography import x509
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

from fleetlog.errors import FormatError
from fleetlog.transport.certs import Certificate, load_certificate, read_certificate, signed_by

__all__ = [
    "Certificate",
    "KeyPair",
    "issue",
    "new_ca",
    "read_certificate",
    "signed_by",
]

#: how long a CA lives, and how long the certificates it signs live by default
CA_DAYS = 3650
CERT_DAYS = 365
#: a little slack for clocks that run behind (vehicles boot without a network clock)
_BACKDATE = dt.timedelta(hours=1)


@dataclass(frozen=True)
class KeyPair:
    """A certificate and its private key, as PEM."""

    cert_pem: bytes
    key_pem: bytes


def _key() -> ec.EllipticCurvePrivateKey:
    return ec.generate_private_key(ec.SECP256R1())


def _pem_key(key: ec.EllipticCurvePrivateKey) -> bytes:
    return key.private_bytes(
        serialization.Encoding.PEM,
        serialization.PrivateFormat.PKCS8,
        serialization.NoEncryption(),
    )


def new_ca(fleet: str, now: dt.datetime, days: int = CA_DAYS) -> KeyPair:
    """Create a fleet's certificate authority (self-signed, may sign end certificates only)."""
    key = _key()
    name = x509.Name(
        [
            x509.NameAttribute(NameOID.ORGANIZATION_NAME, "fleetlog"),
            x509.NameAttribute(NameOID.COMMON_NAME, f"fleetlog CA {fleet}"),
        ]
    )
    cert = (
        x509.CertificateBuilder()
        .subject_name(name)
        .issuer_name(name)
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - _BACKDATE)
        .not_valid_after(now + dt.timedelta(days=days))
        .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
        .add_extension(
            x509.KeyUsage(
                digital_signature=True,
                content_commitment=False,
                key_encipherment=False,
                data_encipherment=False,
                key_agreement=False,
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
    return KeyPair(cert.public_bytes(serialization.Encoding.PEM), _pem_key(key))


def _san(names: tuple[str, ...]) -> list[x509.GeneralName]:
    out: list[x509.GeneralName] = []
    for name in names:
        try:
            out.append(x509.IPAddress(ipaddress.ip_address(name)))
        except ValueError:
            out.append(x509.DNSName(name))
    return out


def issue(
    ca: KeyPair,
    common_name: str,
    now: dt.datetime,
    *,
    names: tuple[str, ...] = (),
    days: int = CERT_DAYS,
) -> KeyPair:
    """Issue a certificate for client and server use, signed by the fleet's CA.

    Args:
        ca: the CA's certificate and key.
        common_name: the identity (``fleetlog:vehicle:alpha``).
        now: the issue time.
        names: host names and IP addresses the holder is reached at (routers).
        days: how long it is valid.

    Raises:
        FormatError: the CA's files are not a certificate and key.
    """
    ca_cert = load_certificate(ca.cert_pem, "the CA certificate")
    try:
        ca_key = serialization.load_pem_private_key(ca.key_pem, password=None)
    except (ValueError, TypeError) as err:
        msg = f"the CA key is not a PEM private key without a password: {err}"
        raise FormatError(msg) from None
    if not isinstance(ca_key, ec.EllipticCurvePrivateKey):
        msg = "the CA key is not an ECDSA key made by fleetlog deploy init"
        raise FormatError(msg)
    key = _key()
    builder = (
        x509.CertificateBuilder()
        .subject_name(x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, common_name)]))
        .issuer_name(ca_cert.subject)
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - _BACKDATE)
        .not_valid_after(min(now + dt.timedelta(days=days), ca_cert.not_valid_after_utc))
        .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
        .add_extension(
            x509.ExtendedKeyUsage(
                [ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH]
            ),
            critical=False,
        )
        .add_extension(
            x509.AuthorityKeyIdentifier.from_issuer_public_key(ca_key.public_key()),
            critical=False,
        )
    )
    if names:
        builder = builder.add_extension(x509.SubjectAlternativeName(_san(names)), critical=False)
    cert = builder.sign(ca_key, hashes.SHA256())
    return KeyPair(cert.public_bytes(serialization.Encoding.PEM), _pem_key(key))
