"""Between hosts: Zenoh access control on a real `astrodyn router`, with plain zenoh clients.

The router runs with user/password authentication and an ACL that denies by default and
lets only the user ``alice`` put on the scene's keys (docs/security.md, "Opening to a
network").  Three publisher processes put on ``astrodyn/demo/sat/orbit``: alice (allowed),
mallory (valid credentials, not in the policy) and eve (wrong password).  A subscriber
(alice) receives alice's samples and nothing from the other two.  Every process is a
plain zenoh client (no astrodyn import), stopped by its PID.
"""

from __future__ import annotations

import json
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


def _router_config(tmp_path) -> str:
    users = tmp_path / "users.txt"
    users.write_text("alice:alice-pw\nmallory:mallory-pw\n")
    users.chmod(0o600)
    conf = tmp_path / "router.json5"
    conf.write_text(textwrap.dedent(f'''
        {{
          transport: {{ auth: {{ usrpwd: {{ dictionary_file: "{users}" }} }} }},
          {scene_acl('usernames: ["alice"]')}
        }}
    '''))
    return str(conf)


@pytest.mark.slow  # CI time (9 s; the router's mTLS policy test (test_router_tls) stays in make test)
def test_acl_on_a_real_router_blocks_publishers_it_does_not_allow(tmp_path, processes):
    port = bus.free_port()
    endpoint = bus.loopback_endpoint(port)
    router = processes([sys.executable, "-m", "astrodyn", "router", "--config", _router_config(tmp_path),
                        "--listen", endpoint], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    hello = json.loads(router.stdout.readline())
    assert hello["listen"] == [endpoint]

    def login(user: str, password: str) -> str:
        return json.dumps({"transport/auth/usrpwd": {"user": user, "password": password}})

    passwords = {"alice": "alice-pw", "mallory": "mallory-pw", "eve": "not-her-password"}
    results, got = publish_to_one_subscriber(processes, endpoint, lambda name: login(name, passwords[name]), "alice",
                                             passwords)
    assert results["alice"] == {"sent": 20} and results["mallory"] == {"sent": 20}
    assert "refused" in results["eve"]  # wrong password: no session at all
    assert got == [f"alice-{i}" for i in range(20)]  # mallory's puts never arrive
