"""A sweep on a Dask cluster reached over TLS with certificates made here; security-file errors."""

from __future__ import annotations

import datetime
import ipaddress
from pathlib import Path

import pytest
from test_sweep import assert_same_rows, rows_of, write_sweep

from qpbench.cli import main

pytest.importorskip("distributed")
pytest.importorskip("cryptography")


def make_certificates(folder: Path) -> tuple[Path, Path, Path]:
    """A certificate authority and one certificate it signs (for 127.0.0.1 and localhost): PEM files."""
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import NameOID

    now = datetime.datetime.now(datetime.timezone.utc)

    def build(subject, issuer, public_key, signing_key, ca: bool):
        builder = (
            x509.CertificateBuilder()
            .subject_name(subject)
            .issuer_name(issuer)
            .public_key(public_key)
            .serial_number(x509.random_serial_number())
            .not_valid_before(now - datetime.timedelta(minutes=5))
            .not_valid_after(now + datetime.timedelta(days=1))
            .add_extension(x509.BasicConstraints(ca=ca, path_length=None), critical=True)
        )
        if not ca:
            builder = builder.add_extension(
                x509.SubjectAlternativeName(
                    [x509.DNSName("localhost"), x509.IPAddress(ipaddress.ip_address("127.0.0.1"))]
                ),
                critical=False,
            )
        return builder.sign(signing_key, hashes.SHA256())

    ca_key = ec.generate_private_key(ec.SECP256R1())
    ca_name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, "qpbench test CA")])
    ca_cert = build(ca_name, ca_name, ca_key.public_key(), ca_key, ca=True)
    key = ec.generate_private_key(ec.SECP256R1())
    cert = build(
        x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, "localhost")]),
        ca_name,
        key.public_key(),
        ca_key,
        ca=False,
    )
    paths = folder / "ca.pem", folder / "node.pem", folder / "node-key.pem"
    paths[0].write_bytes(ca_cert.public_bytes(serialization.Encoding.PEM))
    paths[1].write_bytes(cert.public_bytes(serialization.Encoding.PEM))
    paths[2].write_bytes(
        key.private_bytes(
            serialization.Encoding.PEM,
            serialization.PrivateFormat.PKCS8,
            serialization.NoEncryption(),
        )
    )
    return paths


def test_sweep_on_a_tls_cluster(tmp_path):
    from distributed import LocalCluster

    from qpbench.runner import load_security

    ca, cert, key = make_certificates(tmp_path)
    security_file = tmp_path / "tls.toml"
    security_file.write_text(
        f'ca_file = "{ca.name}"\ncert_file = "{cert.name}"\nkey_file = "{key.name}"\n'
    )
    sweep = write_sweep(tmp_path)
    serial = tmp_path / "serial"
    assert (
        main(["sweep", str(sweep), "--backends", "daqp", "--out", str(serial), "--jobs", "1"]) == 0
    )
    with LocalCluster(
        n_workers=2,
        threads_per_worker=1,
        processes=True,
        host="127.0.0.1",
        dashboard_address=None,
        protocol="tls://",
        security=load_security(security_file),
    ) as cluster:
        address = cluster.scheduler_address
        assert address.startswith("tls://127.0.0.1:")
        out = tmp_path / "out"

        def sweep_on(folder, scheduler: str, *options: str) -> int:
            return main(
                [
                    "sweep",
                    str(sweep),
                    "--backends",
                    "daqp",
                    "--out",
                    str(folder),
                    "--executor",
                    "dask",
                    "--scheduler",
                    scheduler,
                    *options,
                ]
            )

        assert sweep_on(out, address, "--security", str(security_file)) == 0
        # no certificate, no service: a plain client is refused
        assert sweep_on(tmp_path / "x", address.replace("tls://", "tcp://")) == 2
    rows = rows_of(out)
    assert_same_rows(rows_of(serial), rows)
    assert all(r["executor"] == "dask" and r["worker"].startswith("tls://127.0.0.1:") for r in rows)


@pytest.mark.parametrize(
    ("args", "words"),
    [
        (["--scheduler", "tls://127.0.0.1:1"], "needs --security"),
        (["--scheduler", "tcp://127.0.0.1:1", "--security", "{sec}"], "needs a tls:// scheduler"),
        (["--scheduler", "tls://127.0.0.1:1", "--security", "{bad}"], "key 'key_file'"),
    ],
)
def test_security_errors_are_one_line(tmp_path, capsys, args, words):
    (tmp_path / "ca.pem").write_text("x")
    (tmp_path / "sec.toml").write_text(
        'ca_file = "ca.pem"\ncert_file = "ca.pem"\nkey_file = "ca.pem"\n'
    )
    (tmp_path / "bad.toml").write_text(
        'ca_file = "ca.pem"\ncert_file = "ca.pem"\nkey_file = "missing.pem"\n'
    )
    args = [a.format(sec=tmp_path / "sec.toml", bad=tmp_path / "bad.toml") for a in args]
    code = main(
        [
            "sweep",
            str(write_sweep(tmp_path)),
            "--backends",
            "daqp",
            "--out",
            str(tmp_path / "out"),
            "--executor",
            "dask",
        ]
        + args
    )
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and words in err[0], err
    assert not (tmp_path / "out").exists()
