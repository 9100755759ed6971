"""Certificates as fleetlog reads them: who they name, until when, and who signed them.

Used to show a machine's identity and expiry (``status``, ``deploy check``) and to say why a
TLS session could not open, instead of Zenoh's "Unable to connect".
"""

from __future__ import annotations

import datetime as dt
from dataclasses import dataclass

from cryptography import x509
from cryptography.exceptions import InvalidSignature
from cryptography.x509.oid import NameOID

from fleetlog.errors import FormatError

__all__ = ["Certificate", "load_certificate", "read_certificate", "signed_by"]


@dataclass(frozen=True)
class Certificate:
    """What fleetlog reads from a certificate."""

    common_name: str
    issuer: str
    not_before: dt.datetime
    not_after: dt.datetime
    serial: int
    names: tuple[str, ...]
    is_ca: bool

    def days_left(self, now: dt.datetime) -> float:
        """Days until it expires (negative once expired)."""
        return (self.not_after - now).total_seconds() / 86400.0


def _cn(name: x509.Name) -> str:
    attrs = name.get_attributes_for_oid(NameOID.COMMON_NAME)
    value = attrs[0].value if attrs else ""
    return value if isinstance(value, str) else value.decode("utf-8", "replace")


def load_certificate(pem: bytes, what: str) -> x509.Certificate:
    """Parse a PEM certificate.

    Raises:
        FormatError: not a PEM certificate (the message names ``what``).
    """
    try:
        return x509.load_pem_x509_certificate(pem)
    except ValueError as err:
        msg = f"{what} is not a PEM certificate: {err}"
        raise FormatError(msg) from None


def read_certificate(pem: bytes, what: str = "certificate") -> Certificate:
    """Read the parts of a PEM certificate fleetlog shows and checks.

    Raises:
        FormatError: not a PEM certificate.
    """
    cert = load_certificate(pem, what)
    names: list[str] = []
    try:
        san = cert.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
        names = [str(n) for n in san.get_values_for_type(x509.DNSName)]
        names += [str(n) for n in san.get_values_for_type(x509.IPAddress)]
    except x509.ExtensionNotFound:
        pass
    try:
        is_ca = cert.extensions.get_extension_for_class(x509.BasicConstraints).value.ca
    except x509.ExtensionNotFound:
        is_ca = False
    return Certificate(
        common_name=_cn(cert.subject),
        issuer=_cn(cert.issuer),
        not_before=cert.not_valid_before_utc,
        not_after=cert.not_valid_after_utc,
        serial=cert.serial_number,
        names=tuple(names),
        is_ca=is_ca,
    )


def signed_by(cert_pem: bytes, ca_pem: bytes) -> bool:
    """Whether ``cert_pem`` was signed by the CA in ``ca_pem``.

    Raises:
        FormatError: either is not a PEM certificate.
    """
    cert = load_certificate(cert_pem, "the certificate")
    ca = load_certificate(ca_pem, "the CA certificate")
    if cert.issuer != ca.subject:
        return False
    try:
        cert.verify_directly_issued_by(ca)
    except (InvalidSignature, ValueError, TypeError):
        return False
    return True


def check_tls_files(files: dict[str, str], now: dt.datetime | None = None) -> str:
    """One sentence on what is wrong with a configuration's TLS files, or what may be.

    Args:
        files: the ``transport/link/tls`` settings that name files, by setting name.
        now: the time to check expiry against (the clock by default).
    """
    now = now or dt.datetime.now(dt.UTC)
    if "connect_certificate" not in files:
        return (
            "this configuration shows no certificate (transport/link/tls/connect_certificate):"
            " a router with mutual TLS refuses it"
        )
    pems: dict[str, bytes] = {}
    for setting, path in files.items():
        try:
            with open(path, "rb") as f:
                pems[setting] = f.read(1 << 20)
        except OSError as err:
            return f"cannot read {path} (transport/link/tls/{setting}): {err.strerror or err}"
    for setting in ("connect_certificate", "listen_certificate"):
        if setting not in pems:
            continue
        try:
            cert = read_certificate(pems[setting], files[setting])
        except FormatError as err:
            return str(err)
        if cert.not_after < now:
            return (
                f"this machine's certificate {files[setting]} expired on {cert.not_after:%Y-%m-%d}"
            )
        if cert.not_before > now:
            return (
                f"this machine's certificate {files[setting]} is valid only from"
                f" {cert.not_before:%Y-%m-%d %H:%M} UTC (is the clock right?)"
            )
        ca = pems.get("root_ca_certificate")
        if ca is not None:
            try:
                ours = signed_by(pems[setting], ca)
            except FormatError as err:
                return str(err)
            if not ours:
                return (
                    f"this machine's certificate {files[setting]} was not signed by the CA in"
                    f" {files['root_ca_certificate']} (a certificate of another fleet?)"
                )
    return (
        "the TLS handshake failed or nothing listens there: the router may not be up, its"
        " certificate may not be from this fleet's CA or not name the address dialled, or it"
        " refused this certificate (another fleet's CA)"
    )
