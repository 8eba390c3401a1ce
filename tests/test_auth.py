"""Run identity on the bus (astrodyn.auth): authenticators, secret files, control tokens, and
the plant's ``ADP1`` part with which a holder of the control token checks ticks and events.

The MAC is checked against an HMAC-SHA256 written out here from RFC 2104 (ipad / opad over
hashlib.sha256), over the layout documented in astrodyn.auth, so the documented format,
not only the round trip, is what is tested.  The control-token test uses a real client
process that imports only zenoh.
"""

from __future__ import annotations

import hashlib
import json
import os
import stat
import struct
import subprocess
import sys
import textwrap
import time

import pytest
from hypothesis import given, settings, strategies as st

from astrodyn import auth, bus


def rfc2104_hmac_sha256(key: bytes, msg: bytes) -> bytes:
    block = 64
    if len(key) > block:
        key = hashlib.sha256(key).digest()
    key = key.ljust(block, b"\0")
    inner = hashlib.sha256(bytes(k ^ 0x36 for k in key) + msg).digest()
    return hashlib.sha256(bytes(k ^ 0x5C for k in key) + inner).digest()


def test_rfc2104_reference_matches_rfc4231_case_2():
    # RFC 4231 test case 2, so the reference below is itself checked against a published value
    mac = rfc2104_hmac_sha256(b"Jefe", b"what do ya want for nothing?")
    assert mac.hex() == "5bdcc146bf60754e6a042426089575c75a003f089d2739839dec58b964ec3843"


def test_authenticator_layout_and_mac_follow_the_documented_format():
    secret = auth.RunSecret.generate()
    signer = auth.Signer(secret, "orbit")
    key, payload = "astrodyn/demo/iss/orbit", b'{"t":0.0,"seq":0}'
    a1 = signer.attachment(key, payload)
    a2 = signer.attachment(key, payload)
    for n, a in enumerate((a1, a2), start=1):
        assert a[:4] == b"ADA1" and a[4] == len(b"orbit") and a[5:10] == b"orbit"
        instance = a[10:18]
        (counter,) = struct.unpack_from("<Q", a, 18)
        assert counter == n
        header = a[:26]
        assert a[26:] == rfc2104_hmac_sha256(secret.key, header + key.encode() + b"\0" + payload)
    assert a1[10:18] == instance  # one instance per signer
    assert auth.Signer(secret, "orbit").attachment(key, payload)[10:18] != instance


def test_verify_returns_the_process_and_rejects_replays():
    secret = auth.RunSecret.generate()
    signer, verifier = auth.Signer(secret, "attitude"), auth.Verifier(secret)
    key = "astrodyn/s/b/attitude"
    atts = [signer.attachment(key, b"p%d" % i) for i in range(3)]
    assert verifier.verify(key, b"p0", atts[0]) == "attitude"
    assert verifier.verify(key, b"p2", atts[2]) == "attitude"
    for payload, a in ((b"p2", atts[2]), (b"p1", atts[1]), (b"p0", atts[0])):  # same or older counter
        with pytest.raises(auth.AuthError) as e:
            verifier.verify(key, payload, a)
        assert e.value.reason == "replay"
    # a restarted process (new signer, same secret) starts its own counters
    assert verifier.verify(key, b"x", auth.Signer(secret, "attitude").attachment(key, b"x")) == "attitude"


def test_every_single_bit_flip_is_rejected():
    secret = auth.RunSecret.generate()
    signer = auth.Signer(secret, "orbit")
    key, payload = "astrodyn/s/b/orbit", b'{"t":1.5,"seq":7,"r":[1,2,3]}'
    att = signer.attachment(key, payload)
    for i in range(len(payload) * 8):
        bad = bytearray(payload)
        bad[i // 8] ^= 1 << (i % 8)
        with pytest.raises(auth.AuthError):
            auth.Verifier(secret).verify(key, bytes(bad), att)
    for i in range(len(att) * 8):
        bad = bytearray(att)
        bad[i // 8] ^= 1 << (i % 8)
        with pytest.raises(auth.AuthError):
            auth.Verifier(secret).verify(key, payload, bytes(bad))
    with pytest.raises(auth.AuthError) as e:  # the key is covered: same sample on another key
        auth.Verifier(secret).verify("astrodyn/s/ghost/orbit", payload, att)
    assert e.value.reason == "bad-mac"
    with pytest.raises(auth.AuthError) as e:  # another run's secret
        auth.Verifier(auth.RunSecret.generate()).verify(key, payload, att)
    assert e.value.reason == "bad-mac"
    with pytest.raises(auth.AuthError) as e:
        auth.Verifier(secret).verify(key, payload, None)
    assert e.value.reason == "unsigned"


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=300), st.binary(max_size=64))
def test_arbitrary_attachments_only_ever_raise_auth_error(attachment, payload):
    v = auth.Verifier(auth.RunSecret.generate())
    with pytest.raises(auth.AuthError) as e:
        v.verify("astrodyn/s/b/orbit", payload, attachment)
    assert e.value.reason in auth.REJECT_REASONS


def test_forged_headers_with_valid_length_are_rejected_without_growing_state():
    secret = auth.RunSecret.generate()
    v = auth.Verifier(secret)
    for n in range(2000):  # a forger cycling instances and counters
        forged = b"ADA1" + bytes([5]) + b"orbit" + os.urandom(8) + struct.pack("<Q", n) + os.urandom(32)
        with pytest.raises(auth.AuthError):
            v.verify("astrodyn/s/b/orbit", b"{}", forged)
    assert len(v._last) == 0  # private on purpose: the bound is the point of this test


def test_secret_file_is_private_and_checked(tmp_path):
    secret = auth.RunSecret.generate()
    path = secret.save(tmp_path)
    assert stat.S_IMODE(path.stat().st_mode) == 0o600
    assert auth.RunSecret.load(path).key == secret.key
    assert "hidden" in repr(secret) and secret.key.hex() not in repr(secret)
    with pytest.raises(FileExistsError):  # never replaces a file
        secret.save(tmp_path)
    os.chmod(path, 0o644)
    with pytest.raises(auth.AuthError, match="0600"):
        auth.RunSecret.load(path)
    short = auth.write_private_file(tmp_path / "short", b"abc")
    with pytest.raises(auth.AuthError, match="32 bytes"):
        auth.RunSecret.load(short)
    assert auth.secret_from_environment({}) is None
    os.chmod(path, 0o600)
    assert auth.secret_from_environment({auth.SECRET_ENV: str(path)}).key == secret.key


def test_tokens():
    t = auth.new_token()
    assert len(t) >= 43 and auth.token_matches(t, auth.token_from_attachment(auth.token_attachment(t)))
    assert not auth.token_matches(t, None)
    assert not auth.token_matches(t, t[:-1] + ("A" if t[-1] != "A" else "B"))
    assert auth.token_from_attachment(b"ADA1" + t.encode()) is None
    assert auth.token_from_attachment(b"ADT1\xff\xfe") is None
    assert auth.token_from_attachment(b"ADT1" + b"x" * 10_000) is None


# --------------------------------------------------------------------------- the plant's part for token holders

TICK = "astrodyn/demo/@tick"


def _reference_part(token: bytes, key: str, payload: bytes, counter: int) -> bytes:
    """The ADP1 part as docs/control.md writes it out, from the RFC 2104 reference above."""
    plant_key = rfc2104_hmac_sha256(token, b"ADP1 plant tick v1")
    header = b"ADP1" + struct.pack("<Q", counter)
    return header + rfc2104_hmac_sha256(plant_key, header + key.encode() + b"\0" + payload)


def test_plant_part_layout_key_derivation_and_counters_follow_the_documented_format():
    token = auth.new_token()
    signer = auth.PlantSigner(token)
    payload = b'{"t":0.0,"seq":0,"step":0,"samples":{}}'
    parts = [signer.part(TICK, payload) for _ in range(3)]
    for n, part in enumerate(parts, start=1):  # per key 1, 2, 3, ... (a tick put again gets the next)
        assert len(part) == 44 == auth.PLANT_PART_BYTES
        assert part == _reference_part(token.encode(), TICK, payload, n)
    event = "astrodyn/demo/@event"
    assert signer.part(event, b"{}") == _reference_part(token.encode(), event, b"{}", 1)  # its own counter
    # the token file's text: surrounding whitespace is not part of the token
    assert auth.PlantSigner(token + "\n").part(TICK, payload) == parts[0]
    assert auth.plant_key(token.encode()) == rfc2104_hmac_sha256(token.encode(), b"ADP1 plant tick v1")


def test_plant_part_verifies_with_the_token_and_nothing_else():
    token = auth.new_token()
    secret = auth.RunSecret.generate()
    both = auth.WithPlantPart(auth.Signer(secret, "plant"), auth.PlantSigner(token))
    payload = b'{"t":0.1,"seq":1,"step":1,"samples":{"sc/gyro":{"t":0.1,"seq":1,"w":[0,0,0]}}}'
    a = both.attachment(TICK, payload)
    assert len(a) == 5 + 5 + 8 + 8 + 32 + 44 and a[:10] == b"ADA1\x05plant" and a[58:62] == b"ADP1"
    assert a[58:] == _reference_part(token.encode(), TICK, payload, 1)
    assert auth.PlantVerifier(token).verify(TICK, payload, a) == 1
    alone = auth.WithPlantPart(None, auth.PlantSigner(token)).attachment(TICK, payload)  # a plant without the secret
    assert alone == a[58:] and auth.PlantVerifier(token).verify(TICK, payload, alone) == 1

    def reason(v, key, data, att):
        with pytest.raises(auth.AuthError) as e:
            v.verify(key, data, att)
        assert e.value.reason in auth.REJECT_REASONS
        return e.value.reason

    other = auth.new_token()
    assert reason(auth.PlantVerifier(other), TICK, payload, a) == "bad-mac"  # another run's token
    forged = _reference_part(other.encode(), TICK, payload, 7)  # well-formed, keyed by a token the forger made up
    assert reason(auth.PlantVerifier(token), TICK, payload, forged) == "bad-mac"
    assert reason(auth.PlantVerifier(token), "astrodyn/other/@tick", payload, a) == "bad-mac"  # the key is covered
    for i in range(len(payload) * 8):  # every bit of the payload
        bad = bytearray(payload)
        bad[i // 8] ^= 1 << (i % 8)
        assert reason(auth.PlantVerifier(token), TICK, bytes(bad), a) == "bad-mac"
    for i in range(44 * 8):  # every bit of the part: magic, counter, MAC
        bad = bytearray(a)
        bad[58 + i // 8] ^= 1 << (i % 8)
        assert reason(auth.PlantVerifier(token), TICK, payload, bytes(bad)) in ("unsigned", "bad-mac")
    assert reason(auth.PlantVerifier(token), TICK, payload, a[:58]) == "unsigned"  # the ADA1 part alone
    assert reason(auth.PlantVerifier(token), TICK, payload, None) == "unsigned"
    assert reason(auth.PlantVerifier(token), TICK, payload, b"junk" + alone) == "malformed"
    v = auth.PlantVerifier(token)  # replays: the same or an older counter
    a2 = both.attachment(TICK, payload)
    assert v.verify(TICK, payload, a2) == 2
    assert reason(v, TICK, payload, a2) == "replay" and reason(v, TICK, payload, a) == "replay"
    assert v.verify(TICK, payload, both.attachment(TICK, payload)) == 3


def test_the_run_verifier_still_checks_the_ada1_part_and_takes_the_plant_part_only_on_ticks_and_events():
    token, secret = auth.new_token(), auth.RunSecret.generate()
    both = auth.WithPlantPart(auth.Signer(secret, "plant"), auth.PlantSigner(token))
    for key in (TICK, "astrodyn/demo/@event"):
        a = both.attachment(key, b"{}")
        assert auth.Verifier(secret).verify(key, b"{}", a) == "plant"
        for i in range(58 * 8):  # the ADA1 part is checked as before, bit for bit
            bad = bytearray(a)
            bad[i // 8] ^= 1 << (i % 8)
            with pytest.raises(auth.AuthError):
                auth.Verifier(secret).verify(key, b"{}", bytes(bad))
        with pytest.raises(auth.AuthError) as e:  # 44 bytes after it that are not an ADP1 part
            auth.Verifier(secret).verify(key, b"{}", a[:58] + b"XXXX" + a[62:])
        assert e.value.reason == "malformed"
        with pytest.raises(auth.AuthError) as e:
            auth.Verifier(secret).verify(key, b"{}", a + b"x")
        assert e.value.reason == "malformed"
    state = "astrodyn/demo/sc/attitude"  # anywhere else an attachment is the ADA1 authenticator alone
    with pytest.raises(auth.AuthError) as e:
        auth.Verifier(secret).verify(state, b"{}", both.attachment(state, b"{}"))
    assert e.value.reason == "malformed"


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=200), st.binary(max_size=64))
def test_arbitrary_attachments_on_a_tick_only_ever_raise_auth_error(attachment, payload):
    for v in (auth.PlantVerifier(auth.new_token()), auth.Verifier(auth.RunSecret.generate())):
        with pytest.raises(auth.AuthError) as e:
            v.verify(TICK, payload, attachment)
        assert e.value.reason in auth.REJECT_REASONS


_PLAIN_CLIENT = textwrap.dedent("""
    import json, sys, zenoh
    endpoint, key, token = sys.argv[1], sys.argv[2], sys.argv[3]
    conf = zenoh.Config()
    conf.insert_json5("mode", '"client"')
    conf.insert_json5("connect/endpoints", json.dumps([endpoint]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    with zenoh.open(conf) as s:
        att = None if token == "-" else b"ADT1" + token.encode()
        out = []
        for reply in s.get(key, payload=json.dumps({"factor": 2}), attachment=att, timeout=5.0):
            raw = reply.ok.payload.to_bytes() if reply.ok is not None else reply.err.payload.to_bytes()
            out.append(json.loads(raw))
        print(json.dumps(out))
""")


@pytest.mark.network
def test_control_needs_the_token_from_a_plain_zenoh_client(tmp_path):
    token = auth.new_token()
    port = bus.free_port()
    endpoint = bus.loopback_endpoint(port)
    script = tmp_path / "client.py"
    script.write_text(_PLAIN_CLIENT)
    with bus.open_session(listen=[endpoint]) as session, \
            bus.ControlServer(session, "tok", verbs=("rate",), token=token) as control:
        key = "astrodyn/tok/@control/rate"
        results = {}
        for name, presented in (("none", "-"), ("wrong", auth.new_token()), ("right", token)):
            proc = subprocess.Popen([sys.executable, str(script), endpoint, key, presented],
                                    stdout=subprocess.PIPE, stderr=subprocess.PIPE)
            deadline = time.monotonic() + 30
            while proc.poll() is None and time.monotonic() < deadline:
                for req in control.poll():
                    req.reply({"ok": True, "args": req.args})
                time.sleep(0.01)
            if proc.poll() is None:
                proc.kill()
            out, err = proc.communicate(timeout=10)
            assert proc.returncode == 0, err.decode()
            results[name] = json.loads(out)
    assert "unauthorised" in results["none"][0]["error"]
    assert "unauthorised" in results["wrong"][0]["error"]
    assert results["right"] == [{"ok": True, "args": {"factor": 2}}]
    assert control.rejected == {"rate": 2}
