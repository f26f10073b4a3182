"""The credentials of a run over machines: mutual TLS on every Dask link of the run.

A run's simulator and its machines each present the one certificate in the credentials file, and
each accepts only a peer whose certificate the file's CA signed. The CA is the run's own and
throwaway: its private key signs the certificate and is dropped at once, so the file's certificate
is the only one that will ever chain to it. Holding the file is being invited: a process without it
is refused at the TLS handshake, before a byte of Dask reaches the simulator, and a machine cannot be
lured by an impostor simulator (which would need the same file). A new run (or ``composed-sim
credentials make``) makes new ones; nothing else revokes a file, so it is written readable by its
owner only (docs/distributed.md, "What crosses the network").

The engine is Dask's own ``distributed.security.Security`` (tls://, encryption required); this
module only makes and reads the PEM file. ``cryptography`` comes with the ``cluster`` extra.
"""
from __future__ import annotations

import datetime
import os
import re
import socket
from dataclasses import dataclass
from pathlib import Path

from composed_sim.hosting import HostError

FILE_NAME = "credentials.pem"
VALID_DAYS = 30                 # long enough for a batch job's queue; a run makes fresh ones anyway
_BLOCK = re.compile(r"-----BEGIN ([A-Z ]+)-----\n.*?\n-----END \1-----\n?", re.S)
CA_NAME, MEMBER_NAME = "composed-sim run CA", "composed-sim run member"


@dataclass(frozen=True)
class Credentials:
    """The PEM texts of a credentials file: the run's CA certificate, the members' certificate and
    its private key (in memory: Dask takes PEM contents as well as paths)."""
    ca: str
    certificate: str
    key: str
    path: Path

    def security(self):
        """Dask's ``Security`` for every role (scheduler, worker, client): tls:// only."""
        from distributed.security import Security
        roles = {f"tls_{role}_{part}": text for role in ("client", "scheduler", "worker")
                 for part, text in (("cert", self.certificate), ("key", self.key))}
        return Security(require_encryption=True, tls_ca_file=self.ca, **roles)


def make(path: Path) -> Credentials:
    """A new CA and member certificate, written to ``path`` (0600, created so: never readable by
    others even for a moment); the credentials. An existing file is replaced."""
    try:
        from cryptography import x509
        from cryptography.hazmat.primitives import hashes, serialization
        from cryptography.hazmat.primitives.asymmetric import ec
        from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID
    except ImportError:
        raise HostError("a run over machines needs the cryptography package for its TLS credentials: "
                        "pip install 'composed_sim[cluster]'") from None

    def name(common: str) -> x509.Name:
        return x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, common),
                          x509.NameAttribute(NameOID.ORGANIZATION_NAME, socket.gethostname()[:64] or "?")])

    now = datetime.datetime.now(datetime.timezone.utc)
    lifetime = dict(not_valid_before=now - datetime.timedelta(minutes=5),    # clocks a little apart
                    not_valid_after=now + datetime.timedelta(days=VALID_DAYS))
    ca_key, member_key = ec.generate_private_key(ec.SECP256R1()), ec.generate_private_key(ec.SECP256R1())
    ca = (x509.CertificateBuilder(subject_name=name(CA_NAME), issuer_name=name(CA_NAME),
                                  public_key=ca_key.public_key(), serial_number=x509.random_serial_number(), **lifetime)
          .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
          .add_extension(x509.KeyUsage(digital_signature=False, content_commitment=False, key_encipherment=False,
                                       data_encipherment=False, key_agreement=False, key_cert_sign=True,
                                       crl_sign=True, encipher_only=False, decipher_only=False), critical=True)
          .sign(ca_key, hashes.SHA256()))
    member = (x509.CertificateBuilder(subject_name=name(MEMBER_NAME), issuer_name=ca.subject,
                                      public_key=member_key.public_key(), serial_number=x509.random_serial_number(),
                                      **lifetime)
              .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
              .add_extension(x509.ExtendedKeyUsage([ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH]),
                             critical=False)
              .sign(ca_key, hashes.SHA256()))
    del ca_key              # the CA signs this one certificate and no other, ever
    pem = serialization.Encoding.PEM
    credentials = Credentials(
        ca=ca.public_bytes(pem).decode(), certificate=member.public_bytes(pem).decode(),
        key=member_key.private_bytes(pem, serialization.PrivateFormat.PKCS8, serialization.NoEncryption()).decode(),
        path=path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.unlink(missing_ok=True)
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    with os.fdopen(fd, "w") as f:
        f.write(f"# composed-sim run credentials, made {now:%Y-%m-%d %H:%M} UTC on {socket.gethostname()}: whoever\n"
                f"# holds this file may join the run. Keep it private; a new run makes new ones.\n")
        f.write(credentials.ca + credentials.certificate + credentials.key)
    return credentials


def load(path: Path) -> Credentials:
    """The credentials in ``path``; a HostError starting with the file's name when it is missing,
    unreadable, open to others, or not a credentials file."""
    try:
        mode = path.stat().st_mode
        text = path.read_text()
    except OSError as e:
        raise HostError(f"{path}: {e.strerror or e}") from None
    if mode & 0o077:
        raise HostError(f"{path}: readable by others (mode {mode & 0o777:o}); whoever reads it may "
                        f"join the run: chmod 600 {path}, or make new ones (composed-sim credentials make)")
    blocks = [(m.group(1), m.group(0)) for m in _BLOCK.finditer(text)]
    certificates = [block for kind, block in blocks if kind == "CERTIFICATE"]
    keys = [block for kind, block in blocks if kind.endswith("PRIVATE KEY")]
    if len(certificates) != 2 or len(keys) != 1:
        raise HostError(f"{path}: not a composed-sim credentials file (expected 2 certificates and "
                        f"1 private key, found {len(certificates)} and {len(keys)})")
    return Credentials(ca=certificates[0], certificate=certificates[1], key=keys[0], path=path)


def tls_files_security(ca: Path, certificate: Path, key: Path):
    """Dask's ``Security`` of a client of a cluster the user runs with TLS files of their own."""
    from distributed.security import Security
    for what, path in (("CA", ca), ("certificate", certificate), ("key", key)):
        if not path.is_file():
            raise HostError(f"{path}: no such file (the {what})")
    return Security(require_encryption=True, tls_ca_file=str(ca), tls_client_cert=str(certificate),
                    tls_client_key=str(key))
