"""A plain zenoh client for the router tests: no astrodyn import, stopped by its PID.

``python _zenoh_client.py ENDPOINT SETTINGS_JSON NAME sub SECONDS``: subscribes to
``astrodyn/demo/**``, prints ``{"ready": true}``, then after SECONDS ``{"got": [...]}``.
``python _zenoh_client.py ENDPOINT SETTINGS_JSON NAME pub``: puts ``NAME-0`` .. ``NAME-19``
on ``astrodyn/demo/sat/orbit`` and prints ``{"sent": 20}``.  SETTINGS_JSON maps zenoh
config paths to JSON values (credentials, TLS files).  A refused session prints
``{"refused": "..."}`` and exits 0.
"""

import json
import sys
import time

import zenoh


def scene_acl(subject: str) -> str:
    """The router's JSON5 ``access_control`` block of the tests: deny by default, allow
    put / declare_subscriber on ``astrodyn/demo/**`` to the one ``subject`` (a JSON5
    subject body, e.g. ``usernames: ["alice"]``) -- the policy of docs/security.md."""
    return f"""access_control: {{
            enabled: true,
            default_permission: "deny",
            rules: [
              {{ id: "scene", permission: "allow", flows: ["ingress", "egress"],
                 messages: ["put", "declare_subscriber"], key_exprs: ["astrodyn/demo/**"] }},
            ],
            subjects: [ {{ id: "operators", {subject} }} ],
            policies: [ {{ rules: ["scene"], subjects: ["operators"] }} ],
          }},"""


def publish_to_one_subscriber(start, endpoint: str, settings_of, subscriber: str, publishers, seconds: float = 8.0):
    """The router tests' trial: ``subscriber`` subscribes, each of ``publishers`` puts 20
    samples; returns (each publisher's last JSON line, the samples the subscriber got).
    ``start(argv)`` starts a process (the tests' ``processes`` fixture, which stops it by
    PID); ``settings_of(name)`` is the SETTINGS_JSON of that client."""
    import subprocess

    script = __file__

    def client(name, *role):
        return start([sys.executable, script, endpoint, settings_of(name), name, *role], stdout=subprocess.PIPE,
                     stderr=subprocess.PIPE, text=True)

    sub = client(subscriber, "sub", str(seconds))
    first = sub.stdout.readline()
    assert json.loads(first) == {"ready": True}, sub.stderr.read()[-2000:]
    time.sleep(0.5)
    pubs = {name: client(name, "pub") for name in publishers}
    results = {}
    for name, p in pubs.items():
        out, err = p.communicate(timeout=60)
        assert p.returncode == 0, err[-2000:]
        results[name] = json.loads(out.strip().splitlines()[-1])
    out, _ = sub.communicate(timeout=60)
    return results, json.loads(out.strip().splitlines()[-1])["got"]


def main() -> None:
    endpoint, settings, name, role = sys.argv[1:5]
    conf = zenoh.Config()
    conf.insert_json5("mode", '"client"')
    conf.insert_json5("connect/endpoints", json.dumps([endpoint]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    for path, value in json.loads(settings).items():
        conf.insert_json5(path, json.dumps(value))
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
                s.put("astrodyn/demo/sat/orbit", f"{name}-{i}")
                time.sleep(0.05)
            time.sleep(0.5)
            print(json.dumps({"sent": 20}))


if __name__ == "__main__":
    main()
