"""What a machine runs with, and which certificates expire soon: ``deploy check``, ``status``.

An expired certificate stops a vehicle talking to the shore without a word from Zenoh, so
expiry is shown well before it bites: a warning from :data:`EXPIRY_WARNING_DAYS` days out.
"""

from __future__ import annotations

import datetime as dt
from dataclasses import dataclass
from pathlib import Path

from fleetlog.deploy.kit import CERT_FILES, FleetKit
from fleetlog.errors import FleetlogError, FormatError
from fleetlog.storage.files import read_small
from fleetlog.transport.certs import read_certificate, signed_by
from fleetlog.transport.session import SessionOptions, summarize
from fleetlog.wire.access_profile import parse_common_name

__all__ = ["EXPIRY_WARNING_DAYS", "Finding", "fleet_findings", "machine_findings"]

#: a certificate expiring within this many days is a warning
EXPIRY_WARNING_DAYS = 30


@dataclass(frozen=True, slots=True)
class Finding:
    """One line of a check: ``ok``, ``warning`` or ``error``."""

    level: str
    text: str

    def __str__(self) -> str:
        return f"{self.level}: {self.text}" if self.level != "ok" else self.text


def _expiry(what: str, not_after: dt.datetime, now: dt.datetime) -> Finding:
    days = (not_after - now).total_seconds() / 86400
    when = f"{not_after:%Y-%m-%d}"
    if days < 0:
        return Finding("error", f"{what} expired on {when}: renew it (fleetlog deploy renew)")
    if days < EXPIRY_WARNING_DAYS:
        return Finding(
            "warning",
            f"{what} expires on {when}, in {days:.0f} days: renew it (fleetlog deploy renew)",
        )
    return Finding("ok", f"{what} valid until {when} ({days:.0f} days)")


def machine_findings(options: SessionOptions, now: dt.datetime) -> list[Finding]:
    """Check this machine's Zenoh configuration and its certificate.

    Raises:
        TransportError: the configuration cannot be read.
    """
    summary = summarize(options)
    out = [Finding("ok", f"Zenoh configuration: {summary.source.describe()}")]
    where = ", ".join(summary.connect) or "nothing"
    out.append(Finding("ok", f"mode {summary.mode}, connecting to {where}"))
    if summary.listen:
        out.append(Finding("ok", f"listening on {', '.join(summary.listen)}"))
    if summary.multicast_scouting and summary.tls_files:
        out.append(
            Finding(
                "warning",
                "multicast scouting is on: peers that find each other connect around the"
                " routers' access control (zenoh#2137)",
            )
        )
    clear = [e for e in (*summary.listen, *summary.connect) if not e.startswith("tls/")]
    if summary.tls_files and clear:
        out.append(Finding("warning", f"endpoints without TLS: {', '.join(clear)}"))
    cert_path = summary.tls_files.get("connect_certificate")
    if cert_path is None:
        out.append(Finding("ok", "no certificate: no security profile on this machine"))
        return out
    try:
        pem = read_small(Path(cert_path), "certificate")
        cert = read_certificate(pem, cert_path)
    except FleetlogError as err:
        out.append(Finding("error", str(err)))
        return out
    try:
        who = parse_common_name(cert.common_name)
        out.append(Finding("ok", f"identity {cert.common_name}: {who.role.value} {who.name}"))
    except FormatError as err:
        out.append(Finding("error", f"{err}: the fleet's routers grant it nothing"))
    out.append(_expiry(f"certificate {cert_path}", cert.not_after, now))
    ca_path = summary.tls_files.get("root_ca_certificate")
    if ca_path is not None:
        try:
            ca_pem = read_small(Path(ca_path), "CA certificate")
            ca = read_certificate(ca_pem, ca_path)
            if not signed_by(pem, ca_pem):
                out.append(Finding("error", f"{cert_path} was not signed by the CA {ca_path}"))
            out.append(_expiry(f"CA {ca_path}", ca.not_after, now))
        except FleetlogError as err:
            out.append(Finding("error", str(err)))
    return out


def fleet_findings(kit: FleetKit, now: dt.datetime) -> list[Finding]:
    """Check every certificate of a fleet directory.

    Raises:
        UsageError: no fleet there.
        FormatError: its description is damaged.
    """
    fleet = kit.load()
    out: list[Finding] = []
    ca_path = kit.directory / "ca" / "ca.pem"
    try:
        ca = read_certificate(read_small(ca_path, "CA certificate"), str(ca_path))
        out.append(_expiry("the fleet's CA", ca.not_after, now))
    except FleetlogError as err:
        out.append(Finding("error", str(err)))
    for where, who in fleet.holders():
        path = kit.directory / where / CERT_FILES[who.role][0]
        try:
            cert = read_certificate(read_small(path, "certificate"), str(path))
        except FleetlogError as err:
            out.append(Finding("error", str(err)))
            continue
        if cert.common_name != who.common_name:
            out.append(
                Finding("error", f"{path} names {cert.common_name}, expected {who.common_name}")
            )
        out.append(_expiry(f"{who.common_name} ({where})", cert.not_after, now))
    for revoked in fleet.revoked:
        out.append(Finding("ok", f"revoked {revoked.common_name} on {revoked.when[:10]}"))
    return out
