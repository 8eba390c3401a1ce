"""Between hosts over TLS: mutual TLS and certificate-name access control on a real router.

The set-up of docs/security.md, "Opening to a network", items 1 and 2: `astrodyn router`
listens on a ``tls/`` endpoint with ``enable_mtls``, and its ACL denies by default and
lets only the certificate common name ``alice.example.org`` put on the scene's keys.
A throw-away CA is made with the ``openssl`` command for each test.  Three publishers, all
plain zenoh clients (no astrodyn import) stopped by their PID, put on
``astrodyn/demo/sat/orbit``:

* alice: a certificate of the CA with the allowed name: her samples arrive;
* mallory: a valid certificate of the same CA, a name outside the policy: a session, no samples;
* eve: the allowed *name*, signed by another CA: no session at all.

A fourth client without any certificate is refused too (mTLS), and a subscriber (alice's
certificate) sees exactly alice's samples.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from astrodyn import bus

pytestmark = pytest.mark.network

CLIENT = Path(__file__).resolve().parent / "_zenoh_client.py"  # a plain zenoh client (no astrodyn import)
sys.path.insert(0, str(CLIENT.parent))
from _zenoh_client import publish_to_one_subscriber, scene_acl  # noqa: E402


def _openssl(*args: str, cwd) -> None:
    subprocess.run(["openssl", *args], cwd=cwd, check=True, capture_output=True, timeout=60)


def _make_ca(d, name: str, cn: str) -> None:
    _openssl("req", "-x509", "-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes",
             "-keyout", f"{name}-key.pem", "-out", f"{name}.pem", "-days", "2", "-subj", f"/CN={cn}", cwd=d)


def _make_leaf(d, name: str, cn: str, ca: str) -> None:
    """A certificate for ``cn`` signed by ``ca``, valid for localhost / 127.0.0.1, server and client use."""
    _openssl("req", "-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes",
             "-keyout", f"{name}-key.pem", "-out", f"{name}.csr", "-subj", f"/CN={cn}", cwd=d)
    (d / f"{name}.ext").write_text("subjectAltName=DNS:localhost,IP:127.0.0.1\nbasicConstraints=CA:FALSE\n"
                                   "keyUsage=digitalSignature\nextendedKeyUsage=serverAuth,clientAuth\n")
    _openssl("x509", "-req", "-in", f"{name}.csr", "-CA", f"{ca}.pem", "-CAkey", f"{ca}-key.pem",
             "-CAcreateserial", "-out", f"{name}.pem", "-days", "2", "-extfile", f"{name}.ext", cwd=d)


@pytest.fixture
def pki(tmp_path):
    if shutil.which("openssl") is None:
        pytest.skip("the openssl command is needed to make the test certificates")
    d = tmp_path / "pki"
    d.mkdir()
    _make_ca(d, "ca", "astrodyn test CA")
    _make_ca(d, "rogue", "rogue CA")
    _make_leaf(d, "router", "router.example.org", "ca")
    _make_leaf(d, "alice", "alice.example.org", "ca")
    _make_leaf(d, "mallory", "mallory.example.org", "ca")
    _make_leaf(d, "eve", "alice.example.org", "rogue")  # the right name, the wrong CA
    return d


def _router_config(tmp_path, pki) -> str:
    conf = tmp_path / "router.json5"
    conf.write_text(textwrap.dedent(f'''
        {{
          transport: {{ link: {{ tls: {{
            listen_certificate: "{pki / 'router.pem'}",
            listen_private_key: "{pki / 'router-key.pem'}",
            root_ca_certificate: "{pki / 'ca.pem'}",
            enable_mtls: true,
          }} }} }},
          {scene_acl('cert_common_names: ["alice.example.org"]')}
        }}
    '''))
    return str(conf)


def test_mtls_router_admits_only_certificates_of_its_ca_and_names_in_its_policy(tmp_path, pki, processes):
    port = bus.free_port()
    endpoint = f"tls/localhost:{port}"
    router = processes([sys.executable, "-m", "astrodyn", "router", "--config", _router_config(tmp_path, pki),
                        "--listen", f"tls/127.0.0.1:{port}"],
                       stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    hello = router.stdout.readline()
    assert hello, router.stderr.read()[-2000:]
    assert json.loads(hello)["listen"] == [f"tls/127.0.0.1:{port}"]
    ca = str(pki / "ca.pem")

    def settings(name: str) -> str:
        tls = {"root_ca_certificate": ca}
        if name != "nobody":  # nobody: no client certificate at all
            tls.update(connect_certificate=str(pki / f"{name}.pem"), connect_private_key=str(pki / f"{name}-key.pem"),
                       enable_mtls=True)
        return json.dumps({"transport/link/tls": tls})

    results, got = publish_to_one_subscriber(processes, endpoint, settings, "alice",
                                             ("alice", "mallory", "eve", "nobody"), seconds=10)
    assert results["alice"] == {"sent": 20}
    assert results["mallory"] == {"sent": 20}  # a session (her CA is right), but the ACL drops her puts
    assert "refused" in results["eve"]  # the allowed name from another CA: no TLS session
    assert "refused" in results["nobody"]  # mTLS: no client certificate, no session
    assert got == [f"alice-{i}" for i in range(20)]
