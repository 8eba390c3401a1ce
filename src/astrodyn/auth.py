"""A run's identity on the bus: the run secret, message authenticators, control tokens.

Zenoh does not authenticate publishers: any process that reaches a session's port can put
on any key. A run therefore signs what its own processes publish with a secret that never
travels on the bus or on a command line, and its consumers (logger, supervisor, replay
consumers that opt in) drop every sample that does not verify. The trust model, what it
covers and what it does not: docs/security.md.

The run secret
--------------
``astrodyn run`` / ``serve`` create a :class:`RunSecret` at start (32 bytes from
:func:`os.urandom`), write it to a file readable by the owner only (mode 0600, in the run's
private working directory) and hand its path to the children in the environment variable
:data:`SECRET_ENV` (``ASTRODYN_RUN_SECRET_FILE``). :func:`secret_from_environment` reads it
back in the child. Another user of the machine can read neither the file nor a child's
environment; a process of the same user can (it could also attach a debugger): the secret
protects a run against other users and other hosts, not against its own account.

Authenticator
-------------
Every sample a run's process publishes carries an authenticator in its Zenoh attachment::

    magic     4 bytes   b"ADA1"
    name_len  u8        length of the process name (1..128)
    process   name_len  UTF-8 process name ("orbit", "attitude", "logger", "serve", ...)
    instance  8 bytes   random per signer (a restarted process gets a new one)
    counter   u64 LE    per (signer, key), 1, 2, 3, ... strictly increasing
    mac       32 bytes  HMAC-SHA256(secret, everything above || key || 0x00 || payload)

One authenticator per Zenoh sample, so a batch envelope of 1000 states costs one HMAC
(about 1 us for the header plus the hashing of the payload bytes at ~1 GB/s).
:class:`Verifier` checks the MAC in constant time, then the counter (a replayed sample is
rejected), and returns the authenticated process name; every rejection is a
:class:`AuthError` whose ``reason`` is one of :data:`REJECT_REASONS`.

Control tokens
--------------
Control verbs (``serve``, ``replay``) need the run's control token unless the owner opened
control explicitly (``--open-control``). The token is a random string (:func:`new_token`),
printed to the owner and stored in a 0600 file; a request carries it in its attachment
(:func:`token_attachment`) and the server compares it in constant time
(:func:`token_matches`).

The plant's authenticator for token holders
-------------------------------------------
An outside controller of a closed loop holds the control token, not the run secret, so it
cannot check an ``ADA1`` authenticator.  The plant (given the token) therefore appends a
second part to the attachment of its ``@tick`` and ``@event`` samples, which any holder of
the token checks (:class:`PlantSigner`, :class:`PlantVerifier`; docs/control.md,
"Authentication")::

    plant_key = HMAC-SHA256(token_bytes, b"ADP1 plant tick v1")
                token_bytes: the control token file's text without surrounding whitespace
    part      = b"ADP1" || counter (u64 LE; per key, 1, 2, 3, ... strictly increasing)
                || HMAC-SHA256(plant_key, b"ADP1" || counter || key || 0x00 || payload)
    attachment = ADA1 authenticator (above, when the plant has the run secret) || part

The ``ADA1`` part keeps its length (``5 + name_len + 8 + 8 + 32``, read from its own
header), so :class:`Verifier` checks it as before and, on a ``@tick`` or ``@event`` key
only, accepts exactly one 44-byte ``ADP1`` part after it (which it does not check); on
every other key an attachment must still be the ``ADA1`` authenticator alone.  A token
holder reads the part from the attachment's last 44 bytes.
"""

from __future__ import annotations

import hmac
import os
import secrets
import struct
from dataclasses import dataclass, field
from pathlib import Path

__all__ = [
    "SECRET_ENV",
    "TOKEN_ENV",
    "MAGIC",
    "REJECT_REASONS",
    "AuthError",
    "RunSecret",
    "Signer",
    "Verifier",
    "secret_from_environment",
    "write_private_file",
    "new_token",
    "token_attachment",
    "token_from_attachment",
    "token_matches",
    "read_token_file",
    "PLANT_MAGIC",
    "PLANT_KEY_LABEL",
    "PLANT_PART_BYTES",
    "PLANT_PART_KEYS",
    "plant_key",
    "PlantSigner",
    "PlantVerifier",
    "WithPlantPart",
]

#: Environment variable that holds the path of the run secret file in a run's children.
SECRET_ENV = "ASTRODYN_RUN_SECRET_FILE"
#: Environment variable an outside client may set to the path of a control-token file.
TOKEN_ENV = "ASTRODYN_CONTROL_TOKEN_FILE"
MAGIC = b"ADA1"
SECRET_BYTES = 32
MAC_BYTES = 32
_MAX_NAME = 128
_COUNTER = struct.Struct("<Q")
_TOKEN_MAGIC = b"ADT1"
#: Magic of the plant's authenticator for holders of the control token.
PLANT_MAGIC = b"ADP1"
#: What the plant's key is derived with: ``HMAC-SHA256(token_bytes, PLANT_KEY_LABEL)``.
PLANT_KEY_LABEL = b"ADP1 plant tick v1"
#: Length of the ``ADP1`` part: magic, counter, MAC.
PLANT_PART_BYTES = 4 + 8 + MAC_BYTES
#: Keys (their last chunk) whose samples may carry an ``ADP1`` part after the ``ADA1`` one.
PLANT_PART_KEYS = ("/@tick", "/@event")

#: Why a sample was rejected (the logger counts rejections per reason).
REJECT_REASONS: tuple[str, ...] = ("unsigned", "malformed", "bad-mac", "replay")


class AuthError(ValueError):
    """A sample that does not verify; ``reason`` is one of :data:`REJECT_REASONS`."""

    def __init__(self, reason: str, detail: str = ""):
        super().__init__(f"{reason}: {detail}" if detail else reason)
        self.reason = reason


def write_private_file(path: str | os.PathLike, data: bytes) -> Path:
    """Write ``data`` to a new file at ``path`` readable and writable by the owner only
    (mode 0600 from creation: no moment where another user could open it). Refuses to
    replace an existing file (``FileExistsError``)."""
    path = Path(path)
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0), 0o600)
    try:
        os.write(fd, data)
    finally:
        os.close(fd)
    return path


def _read_private_file(path: str | os.PathLike, what: str) -> bytes:
    path = Path(path)
    try:
        st = path.stat()
        data = path.read_bytes()
    except OSError as exc:
        raise AuthError("malformed", f"{what} {path}: cannot read ({exc.strerror})") from None
    if st.st_mode & 0o077:
        raise AuthError("malformed", f"{what} {path}: expected mode 0600 (owner only), got {oct(st.st_mode & 0o777)}")
    return data


@dataclass(frozen=True, repr=False)
class RunSecret:
    """The 32-byte secret of one run (``repr`` never shows it)."""

    key: bytes

    def __post_init__(self):
        if not isinstance(self.key, bytes) or len(self.key) != SECRET_BYTES:
            raise ValueError(f"run secret: expected {SECRET_BYTES} bytes")

    def __repr__(self) -> str:
        return "RunSecret(<hidden>)"

    @classmethod
    def generate(cls) -> RunSecret:
        """A new secret from :func:`os.urandom`."""
        return cls(os.urandom(SECRET_BYTES))

    def save(self, directory: str | os.PathLike, name: str = "run.secret") -> Path:
        """Write the secret to ``directory/name`` with mode 0600; returns the path (what
        the supervisor puts in :data:`SECRET_ENV` for its children)."""
        return write_private_file(Path(directory) / name, self.key)

    @classmethod
    def load(cls, path: str | os.PathLike) -> RunSecret:
        """Read a secret file written by :meth:`save` (refused unless mode 0600)."""
        data = _read_private_file(path, "run secret file")
        if len(data) != SECRET_BYTES:
            raise AuthError("malformed", f"run secret file {path}: expected {SECRET_BYTES} bytes, got {len(data)}")
        return cls(data)


def secret_from_environment(environ: dict | None = None) -> RunSecret | None:
    """The run secret named by :data:`SECRET_ENV`, or None when the variable is not set
    (a process started by hand, outside a supervisor)."""
    path = (os.environ if environ is None else environ).get(SECRET_ENV)
    return RunSecret.load(path) if path else None


def _mac(secret: bytes, header: bytes, key: str, payload: bytes) -> bytes:
    # one-shot hmac.digest (OpenSSL's C path) is ~2x cheaper per small message than
    # hmac.new + update; the concatenation copies the payload once (~20 us per MB)
    return hmac.digest(secret, b"".join((header, key.encode(), b"\0", payload)), "sha256")


class Signer:
    """Makes the authenticators of one process (see the module docstring).

    ``signer.attachment(key, payload)`` returns the bytes to put in the sample's attachment;
    counters are kept per key, so each key's samples verify in publication order.
    """

    def __init__(self, secret: RunSecret, process: str):
        name = process.encode()
        if not 1 <= len(name) <= _MAX_NAME:
            raise ValueError(f"process name: expected 1..{_MAX_NAME} bytes, got {process!r}")
        self.process = process
        self._secret = secret.key
        self._prefix = MAGIC + bytes([len(name)]) + name + os.urandom(8)
        self._counters: dict[str, int] = {}

    def attachment(self, key: str, payload: bytes) -> bytes:
        n = self._counters.get(key, 0) + 1
        self._counters[key] = n
        header = self._prefix + _COUNTER.pack(n)
        return header + _mac(self._secret, header, key, payload)


@dataclass
class Verifier:
    """Checks authenticators against one run's secret (see the module docstring).

    ``verify(key, payload, attachment)`` returns the authenticated process name or raises
    :class:`AuthError`. Counters are remembered per (process instance, key) only after a MAC
    verified, so a forger cannot grow this state.
    """

    secret: RunSecret
    _last: dict[tuple[bytes, str], int] = field(default_factory=dict, repr=False)

    def verify(self, key: str, payload: bytes, attachment: bytes | None) -> str:
        if not attachment:
            raise AuthError("unsigned", key)
        a = bytes(attachment)
        if len(a) < 4 + 1 + 1 + 8 + 8 + MAC_BYTES or a[:4] != MAGIC:
            raise AuthError("malformed", f"{key}: not an astrodyn authenticator")
        n = a[4]
        header_len = 5 + n + 8 + 8
        end = header_len + MAC_BYTES
        # the plant's ticks and events may carry its part for token holders after ours: not checked here
        if not 1 <= n <= _MAX_NAME or (len(a) != end and not (
                len(a) == end + PLANT_PART_BYTES and a[end:end + 4] == PLANT_MAGIC and key.endswith(PLANT_PART_KEYS))):
            raise AuthError("malformed", f"{key}: authenticator of the wrong length")
        header = a[:header_len]
        if not hmac.compare_digest(a[header_len:end], _mac(self.secret.key, header, key, payload)):
            raise AuthError("bad-mac", key)
        try:
            process = header[5:5 + n].decode()
        except UnicodeDecodeError:
            raise AuthError("malformed", f"{key}: process name is not UTF-8") from None
        instance = header[:5 + n + 8]
        (counter,) = _COUNTER.unpack_from(header, 5 + n + 8)
        last = self._last.get((instance, key), 0)
        if counter <= last:
            raise AuthError("replay", f"{key}: counter {counter} after {last}")
        self._last[(instance, key)] = counter
        return process


# --------------------------------------------------------------------------- the plant, for token holders


def plant_key(token: str | bytes) -> bytes:
    """The key of the plant's ``ADP1`` parts for the control token ``token`` (the token
    file's text without surrounding whitespace): ``HMAC-SHA256(token, PLANT_KEY_LABEL)``."""
    raw = token.encode("ascii") if isinstance(token, str) else bytes(token)
    return hmac.digest(raw.strip(), PLANT_KEY_LABEL, "sha256")


class PlantSigner:
    """Makes the plant's ``ADP1`` parts (module docstring) from the run's control token;
    ``part(key, payload)``: the 44 bytes to append to the sample's attachment."""

    def __init__(self, token: str | bytes):
        self._key = plant_key(token)
        self._counters: dict[str, int] = {}

    def __repr__(self) -> str:
        return "PlantSigner(<hidden>)"

    def part(self, key: str, payload: bytes) -> bytes:
        n = self._counters.get(key, 0) + 1
        self._counters[key] = n
        header = PLANT_MAGIC + _COUNTER.pack(n)
        return header + _mac(self._key, header, key, payload)


class WithPlantPart:
    """The attachment of the plant's ticks and events: ``signer``'s ``ADA1`` authenticator
    (none without the run secret) followed by ``plant``'s ``ADP1`` part.  Has the
    ``attachment(key, payload)`` of a :class:`Signer`, so it signs wherever one does."""

    def __init__(self, signer: Signer | None, plant: PlantSigner):
        self.signer, self.plant = signer, plant

    def attachment(self, key: str, payload: bytes) -> bytes:
        first = b"" if self.signer is None else self.signer.attachment(key, payload)
        return first + self.plant.part(key, payload)


class PlantVerifier:
    """Checks the plant's ``ADP1`` parts with the control token, as an outside controller
    does (module docstring; ``examples/astrodyn_link.py`` is the same in plain Python).

    ``verify(key, payload, attachment)`` returns the part's counter or raises
    :class:`AuthError`: ``unsigned`` (no ``ADP1`` part), ``malformed`` (what precedes it is
    neither nothing nor an ``ADA1`` authenticator of its length), ``bad-mac``, ``replay``
    (a counter not above the last one verified on that key)."""

    def __init__(self, token: str | bytes):
        self._key = plant_key(token)
        self._last: dict[str, int] = {}

    def __repr__(self) -> str:
        return "PlantVerifier(<hidden>)"

    def verify(self, key: str, payload: bytes, attachment: bytes | None) -> int:
        a = bytes(attachment or b"")
        part = a[-PLANT_PART_BYTES:]
        if len(part) != PLANT_PART_BYTES or part[:4] != PLANT_MAGIC:
            raise AuthError("unsigned", f"{key}: no plant authenticator for the control token")
        first = a[:-PLANT_PART_BYTES]
        if first and not (first[:4] == MAGIC and len(first) > 4 and len(first) == 5 + first[4] + 8 + 8 + MAC_BYTES):
            raise AuthError("malformed", f"{key}: unexpected bytes before the plant authenticator")
        header = part[:12]
        if not hmac.compare_digest(part[12:], _mac(self._key, header, key, payload)):
            raise AuthError("bad-mac", key)
        (counter,) = _COUNTER.unpack_from(header, 4)
        last = self._last.get(key, 0)
        if counter <= last:
            raise AuthError("replay", f"{key}: counter {counter} after {last}")
        self._last[key] = counter
        return counter


# --------------------------------------------------------------------------- control tokens


def new_token() -> str:
    """A fresh control token: 43 URL-safe characters (256 random bits)."""
    return secrets.token_urlsafe(32)


def token_attachment(token: str) -> bytes:
    """The attachment that carries ``token`` on a control query."""
    return _TOKEN_MAGIC + token.encode()


def token_from_attachment(attachment: bytes | None) -> str | None:
    """The token carried by a control query's attachment, or None."""
    if not attachment:
        return None
    a = bytes(attachment)
    if a[:4] != _TOKEN_MAGIC or len(a) > 4 + 256:
        return None
    try:
        return a[4:].decode()
    except UnicodeDecodeError:
        return None


def token_matches(expected: str, presented: str | None) -> bool:
    """Constant-time comparison of a presented token with the expected one."""
    return presented is not None and hmac.compare_digest(expected.encode(), presented.encode())


def read_token_file(path: str | os.PathLike) -> str:
    """The control token stored in ``path`` (a 0600 file, as ``serve`` / ``run`` write it);
    :class:`AuthError` if it is unreadable, not private or not a token."""
    data = _read_private_file(path, "control token file").strip()
    try:
        token = data.decode("ascii")
    except UnicodeDecodeError:
        raise AuthError("malformed", f"control token file {path}: not a token") from None
    if not 16 <= len(token) <= 256:
        raise AuthError("malformed", f"control token file {path}: expected 16..256 characters, got {len(token)}")
    return token
