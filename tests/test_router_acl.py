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
import time

import pytest

from astrodyn import bus

pytestmark = pytest.mark.network

CLIENT = textwrap.dedent('''
    import json, sys, time, zenoh
    endpoint, user, pw, role = sys.argv[1:5]
    conf = zenoh.Config()
    conf.insert_json5("mode", '"client"')
    conf.insert_json5("connect/endpoints", json.dumps([endpoint]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("transport/auth/usrpwd", json.dumps({"user": user, "password": pw}))
    try:
        s = zenoh.open(conf)
    except zenoh.ZError as exc:
        print(json.dumps({"refused": str(exc)}))
        sys.exit(0)
    with s:
        if role == "sub":
            sub = s.declare_subscriber("astrodyn/demo/**", zenoh.handlers.FifoChannel(1000))
            print(json.dumps({"ready": True}), flush=True)
            got, t0 = [], time.monotonic()
            while time.monotonic() - t0 < float(sys.argv[5]):
                m = sub.try_recv()
                if m is not None:
                    got.append(m.payload.to_bytes().decode())
                else:
                    time.sleep(0.01)
            print(json.dumps({"got": got}))
        else:
            for i in range(20):
                s.put("astrodyn/demo/sat/orbit", f"{user}-{i}")
                time.sleep(0.05)
            time.sleep(0.5)
            print(json.dumps({"sent": 20}))
''')


def _router_config(tmp_path) -> str:
    users = tmp_path / "users.txt"
    users.write_text("alice:alice-pw\nmallory:mallory-pw\n")
    users.chmod(0o600)
    conf = tmp_path / "router.json5"
    conf.write_text(textwrap.dedent(f'''
        {{
          transport: {{ auth: {{ usrpwd: {{ dictionary_file: "{users}" }} }} }},
          access_control: {{
            enabled: true,
            default_permission: "deny",
            rules: [
              {{ id: "scene", permission: "allow", flows: ["ingress", "egress"],
                 messages: ["put", "declare_subscriber"], key_exprs: ["astrodyn/demo/**"] }},
            ],
            subjects: [ {{ id: "operators", usernames: ["alice"] }} ],
            policies: [ {{ rules: ["scene"], subjects: ["operators"] }} ],
          }},
        }}
    '''))
    return str(conf)


def test_acl_on_a_real_router_blocks_publishers_it_does_not_allow(tmp_path, processes):
    port = bus.free_port()
    endpoint = bus.loopback_endpoint(port)
    script = tmp_path / "client.py"
    script.write_text(CLIENT)
    router = processes([sys.executable, "-m", "astrodyn", "router", "--config", _router_config(tmp_path),
                        "--listen", endpoint], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    hello = json.loads(router.stdout.readline())
    assert hello["listen"] == [endpoint]
    sub = processes([sys.executable, str(script), endpoint, "alice", "alice-pw", "sub", "8"],
                    stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert json.loads(sub.stdout.readline()) == {"ready": True}
    time.sleep(0.5)
    pubs = {name: processes([sys.executable, str(script), endpoint, name, pw, "pub"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
            for name, pw in (("alice", "alice-pw"), ("mallory", "mallory-pw"), ("eve", "not-her-password"))}
    results = {}
    for name, p in pubs.items():
        out, err = p.communicate(timeout=60)
        assert p.returncode == 0, err[-2000:]
        results[name] = json.loads(out.strip().splitlines()[-1])
    out, err = sub.communicate(timeout=60)
    got = json.loads(out.strip().splitlines()[-1])["got"]
    assert results["alice"] == {"sent": 20} and results["mallory"] == {"sent": 20}
    assert "refused" in results["eve"]  # wrong password: no session at all
    assert got == [f"alice-{i}" for i in range(20)]  # mallory's puts never arrive
