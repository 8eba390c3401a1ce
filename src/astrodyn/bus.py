"""The Zenoh bus: sessions with safe defaults, state publishers, liveliness, heartbeats, control.

Every astrodyn process talks over one Zenoh session opened with :func:`open_session`.
The defaults keep a scenario private to the machine:

* ``listen`` on ``tcp/127.0.0.1:<port>`` (an explicit loopback endpoint; :func:`free_port`
  picks the port), never the Zenoh default ``tcp/[::]:0`` that binds every interface;
* multicast scouting **off** (nothing is announced on the LAN);
* gossip scouting **on**: peers that meet through one hub (the runner's session) learn
  each other's loopback locators and connect directly, so a hub-and-spoke start-up gives
  a full mesh.

Multi-host set-ups are explicit: ``connect=["tcp/10.0.0.5:7447"]`` joins a router (or
another peer) and ``listen=["tcp/0.0.0.0:7447"]`` opens a port to the network; put TLS
(``tls/host:port`` endpoints plus the ``transport/link/tls`` settings) and access control
(``access_control`` in the Zenoh config) in front of anything that leaves the machine.
``mode="client"`` makes a session that only connects (it never listens).

Facts measured on eclipse-zenoh 1.10.2 that this module is built around:

* The default congestion control ``DROP`` silently lost half the messages of a subscriber
  that could not keep up.  State publishers therefore use ``CongestionControl.BLOCK`` and
  ``Reliability.RELIABLE`` (:func:`declare_state_publisher`): a slow logger slows the
  propagators down instead of losing states.
* A session left open with a callback subscriber hangs interpreter exit.  Use every session
  as a context manager (``with open_session() as session: ...``); this module only declares
  channel (FIFO) handlers, which are polled from the owner's loop, never Python callbacks.
* A child created by ``fork`` after the parent opened a session hangs.  Start processes with
  ``subprocess`` (or ``multiprocessing`` with the ``spawn`` start method), never ``fork``.
* Liveliness tokens survive a hung Python process (Zenoh's Rust threads keep them alive),
  so a stuck propagator is detected with the application :class:`Heartbeat` as well as with
  :func:`declare_alive` / :class:`AliveWatcher` (which catch a process that exits or is killed).

Key layout (docs/architecture.md, "Processes and keys"; builders live in :mod:`astrodyn.messages`)::

    astrodyn/<scenario>/<body>/orbit | attitude | crosscheck   state messages (JSON)
    astrodyn/<scenario>/@batch/<process>                       batch envelopes of state messages
    astrodyn/<scenario>/@event                                 events (start, stop, restart, error)
    astrodyn/<scenario>/@alive/<process>                       liveliness tokens
    astrodyn/<scenario>/@heartbeat/<process>                   application heartbeats (JSON)
    astrodyn/<scenario>/@control/<verb>                        queryables: status pause resume rate stop
    astrodyn/<scenario>/@status                                the logger's status queryable

Zenoh wildcards never match a chunk that starts with ``@`` (a "verbatim" chunk): the
subscription ``astrodyn/<scenario>/**`` receives the state keys but not ``@batch/...``,
``@event`` or ``@heartbeat/...``.  :func:`scenario_keys` lists the subscriptions that
together cover everything a scenario publishes.
"""

from __future__ import annotations

import argparse
import contextlib
import ipaddress
import json
import math
import os
import re
import socket
import stat
import tempfile
import time
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import zenoh

from astrodyn import auth, messages
from astrodyn.files import file_kind, regular_file_problem

__all__ = [
    "SchemaServer",
    "EventSeqWatcher",
    "LISTENING_GAP_S",
    "ListeningClock",
    "DEFAULT_HOST",
    "process_signer",
    "signed_put",
    "RATE_BOUNDS",
    "parse_rate_factor",
    "rate_argument",
    "CONTROL_VERBS",
    "BusError",
    "free_port",
    "loopback_endpoint",
    "ENDPOINT_PROTOCOLS",
    "host_port_problem",
    "endpoint_problem",
    "check_endpoint",
    "endpoint_argument",
    "ZENOH_CONFIG_MAX_BYTES",
    "zenoh_config_problem",
    "zenoh_config_error_text",
    "ZenohConfigText",
    "read_zenoh_config",
    "make_config",
    "open_session",
    "add_bus_arguments",
    "session_from_args",
    "declare_state_publisher",
    "Publisher",
    "BatchPublisher",
    "EventPublisher",
    "END_EVENT",
    "heartbeat_key",
    "scenario_keys",
    "declare_alive",
    "wait_for_process",
    "wait_for_logger",
    "port_taken",
    "local_port",
    "zenoh_error_text",
    "local_port_problem",
    "AliveWatcher",
    "Heartbeat",
    "HEARTBEAT_PERIOD_S",
    "HeartbeatMonitor",
    "ControlRequest",
    "ControlServer",
    "send_control",
    "query_json",
]

DEFAULT_HOST = "127.0.0.1"
#: The control verbs every long-running astrodyn service answers (``serve``, ``replay``).
CONTROL_VERBS = ("status", "pause", "resume", "rate", "stop")
_MODES = ("peer", "client", "router")


class BusError(RuntimeError):
    """A Zenoh session could not be opened or a bus operation failed (message says which)."""


# --------------------------------------------------------------------------- sessions


def free_port(host: str = DEFAULT_HOST) -> int:
    """A TCP port on ``host`` that is free right now (the OS picks it; bind then release).

    Another process could take it before Zenoh binds it; :func:`open_session` retries with a
    new port when that happens to a port it chose itself.
    """
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind((host, 0))
        return int(sock.getsockname()[1])


def port_taken(port: int, host: str = DEFAULT_HOST) -> str | None:
    """Why TCP ``port`` on ``host`` cannot be listened on now (e.g. "Address already in
    use"), or None if it can; a port another process listens on is taken, one in TIME_WAIT
    is not (SO_REUSEADDR, as the servers set it)."""
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            sock.bind((host, int(port)))
    except OSError as exc:
        return exc.strerror or str(exc)
    return None


def local_port_problem(port: int) -> str | None:
    """What is wrong with ``port`` for a server of this machine's loopback (a ``--port`` or
    ``--foxglove`` option: 0..65535, 0 meaning a free one, and nothing listening on it now,
    so that a taken port is refused by name at the command line, not later in a server's
    own process), as "expected ..., got ..."; None if it will do."""
    if not 0 <= port <= 65535:
        return f"expected a port 0..65535 (0: a free one), got {port}"
    if port and (why := port_taken(port)):
        return f"expected a free port on {DEFAULT_HOST}, got {port} ({why})"
    return None


def local_port(text: str) -> int:
    """argparse type of a port option (:func:`local_port_problem`)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a port 0..65535 (0: a free one), got {str(text)[:40]!r}") from None
    if problem := local_port_problem(value):
        raise argparse.ArgumentTypeError(problem)
    return value


def loopback_endpoint(port: int | None = None) -> str:
    """``tcp/127.0.0.1:<port>`` (a free port when ``port`` is None)."""
    return f"tcp/{DEFAULT_HOST}:{free_port() if port is None else int(port)}"


#: The Zenoh transports an endpoint may name: the IP ones, whose address is HOST:PORT.
ENDPOINT_PROTOCOLS = ("tcp", "udp", "tls", "quic", "ws")

_HOST_LABEL = re.compile(r"^[A-Za-z0-9_]([A-Za-z0-9_-]{0,61}[A-Za-z0-9_])?$")


def host_port_problem(address: str) -> str | None:
    """Why ``address`` is not ``HOST:PORT`` -- HOST an IPv4 address, a bracketed IPv6
    address (``[::1]``) or a host name (RFC 1123 labels), PORT an integer 1..65535 -- or
    None when it is.  The one check of a network address (Zenoh endpoints, the Dask
    scheduler of ``astrodyn sweep``)."""
    host, colon, port = address.rpartition(":")
    if not colon:
        return "no ':PORT' in the address"
    if not host:
        return "no HOST before ':PORT'"
    if not port.isdigit() or not port.isascii():
        return f"port {port[:20]!r} is not an integer"
    if len(port) > 5 or not 1 <= int(port) <= 65535:  # (a 5000-digit port is not even converted)
        return f"port {port if len(port) <= 20 else port[:20] + '...'} is not in 1..65535"
    if host.startswith("["):
        if not host.endswith("]"):
            return f"host {host[:60]!r}: an IPv6 address opened with '[' is not closed with ']'"
        try:
            ipaddress.IPv6Address(host[1:-1].split("%", 1)[0])
        except ValueError:
            return f"host {host[:60]!r} is not an IPv6 address"
        return None
    labels = host.split(".")
    if len(labels) == 4 and all(label.isdigit() for label in labels):
        try:
            ipaddress.IPv4Address(host)
        except ValueError:
            return f"host {host[:60]!r} is not an IPv4 address (4 numbers 0..255)"
        return None
    if len(host) > 253 or not all(_HOST_LABEL.match(label) for label in labels):
        return f"host {host[:60]!r} is not an IPv4 address, [IPv6 address] or host name"
    return None


def endpoint_problem(endpoint: Any) -> str | None:
    """Why ``endpoint`` is not a Zenoh endpoint astrodyn accepts --
    ``PROTOCOL/HOST:PORT[?metadata][#config]`` with PROTOCOL one of
    :data:`ENDPOINT_PROTOCOLS` and the address as :func:`host_port_problem` says, or
    ``unixsock-stream/PATH`` (a Unix socket) -- or None."""
    if not isinstance(endpoint, str):
        return f"not a string but {type(endpoint).__name__}"
    protocol, slash, rest = endpoint.partition("/")
    if not slash:
        return "no PROTOCOL/ before the address"
    address = re.split(r"[?#]", rest, maxsplit=1)[0]
    if protocol == "unixsock-stream":  # a local socket: its address is a file path
        return None if address and "\0" not in address else "no socket path after unixsock-stream/"
    if protocol not in ENDPOINT_PROTOCOLS:
        return f"protocol {protocol[:40]!r} is not one of {', '.join(ENDPOINT_PROTOCOLS)}, unixsock-stream"
    return host_port_problem(address)


def check_endpoint(endpoint: Any, what: str) -> str:
    """``endpoint`` if :func:`endpoint_problem` finds nothing wrong, else BusError naming
    ``what`` (the flag or argument), the form expected and the problem."""
    problem = endpoint_problem(endpoint)
    if problem is not None:
        shown = endpoint[:200] + "..." if isinstance(endpoint, str) and len(endpoint) > 200 else endpoint
        raise BusError(f"{what}: expected Zenoh endpoints like 'tcp/127.0.0.1:7447', got {shown!r}: {problem} "
                       f"(PROTOCOL/HOST:PORT, PROTOCOL one of {', '.join(ENDPOINT_PROTOCOLS)}, HOST an IPv4 address, "
                       f"[IPv6 address] or host name, PORT 1..65535; or unixsock-stream/PATH)")
    return endpoint


_RUST_SOURCE = re.compile(r" at /\S+?\.rs:\d+\.?")


def zenoh_error_text(exc: BaseException | None) -> str:
    """The text of a Zenoh error without the Rust source locations it carries (`` at
    /root/.cargo/git/checkouts/zenoh-.../src/lib.rs:147``): what went wrong, for a user."""
    return _RUST_SOURCE.sub("", str(exc)).strip()


def endpoint_argument(value: str) -> str:
    """The argparse ``type`` of an endpoint flag (``--connect``, ``--listen``): the value, or
    argparse's usage error (exit 2) naming the flag, with :func:`check_endpoint`'s text."""
    try:
        return check_endpoint(value, "endpoint")
    except BusError as exc:
        raise argparse.ArgumentTypeError(str(exc).removeprefix("endpoint: ")) from None


def _endpoint_list(name: str, value: str | Sequence[str] | None) -> list[str]:
    if value is None:
        return []
    items = [value] if isinstance(value, str) else list(value)
    for item in items:
        check_endpoint(item, name)
    return items


#: Largest Zenoh configuration file astrodyn reads (``--zenoh-config`` of every command,
#: ``router --config``), bytes: every process of a run parses it with Zenoh's JSON5 parser,
#: and a config with TLS paths and access-control rules is a few kB.
ZENOH_CONFIG_MAX_BYTES = 2**20

#: Deepest nesting of ``{`` / ``[`` astrodyn hands to Zenoh's parser: its JSON5 parser recurses
#: once per level on the native stack, and ``"[" * 50000`` (100 kB, well under the size limit)
#: killed every command taking ``--zenoh-config`` with SIGSEGV.  Real configs nest 5-8 deep.
ZENOH_CONFIG_MAX_DEPTH = 128

#: What :func:`zenoh_config_depth` skips: JSON5 / YAML strings and comments, whose brackets
#: are text (``"tcp/[::1]:7447"``).
_CONFIG_TEXT = re.compile(rb'"(?:[^"\\\n]|\\.)*"|\'(?:[^\'\\\n]|\\.)*\'|//[^\n]*|/\*.*?(?:\*/|\Z)|#[^\n]*', re.S)


def zenoh_config_depth(data: bytes, limit: int = ZENOH_CONFIG_MAX_DEPTH) -> int:
    """How deep ``{`` and ``[`` nest in the configuration text ``data`` (outside strings and
    comments), counted up to ``limit + 1`` (a deeper text stops the count there)."""
    depth = deepest = 0
    for c in _CONFIG_TEXT.sub(b"", data).translate(None, delete=bytes(set(range(256)) - set(b"{}[]"))):
        depth += 1 if c in b"{[" else -1
        if depth > deepest:
            deepest = depth
            if deepest > limit:
                break
    return deepest


#: The settings of a Zenoh configuration file that decide who can reach a session and that
#: astrodyn sets itself on top of it (:func:`make_config`): a file that sets them gets a warning.
_SETTINGS_ASTRODYN_SETS = ("listen/endpoints", "connect/endpoints", "scouting/multicast/enabled")


def _zenoh_config_size_problem(size: int) -> str | None:
    """The one comparison with :data:`ZENOH_CONFIG_MAX_BYTES`."""
    if size > ZENOH_CONFIG_MAX_BYTES:
        return (f"expected a Zenoh JSON5 configuration of at most {ZENOH_CONFIG_MAX_BYTES // 2**20} MiB "
                f"({ZENOH_CONFIG_MAX_BYTES} bytes), got {size} bytes")
    return None


def _zenoh_config_stat_problem(status: os.stat_result) -> str | None:
    if not stat.S_ISREG(status.st_mode):  # a FIFO would block Zenoh's read for good, a device never ends
        return f"expected a regular file, got {file_kind(status.st_mode)}"
    return _zenoh_config_size_problem(status.st_size)


def zenoh_config_problem(path: str | os.PathLike) -> str | None:
    """What is wrong with ``path`` as a Zenoh configuration file, judged from ``os.stat``
    before anything opens it (which never blocks): not a regular file (a FIFO, a directory,
    a device, no such file), or larger than :data:`ZENOH_CONFIG_MAX_BYTES`; None if it will do.
    The one check of every Zenoh config astrodyn reads (:func:`make_config`,
    :func:`read_zenoh_config`)."""
    if problem := regular_file_problem(path):
        return problem
    try:
        return _zenoh_config_stat_problem(os.stat(path))
    except OSError as exc:
        return f"expected a regular file, got an unreadable path ({exc.strerror or exc})"


#: Zenoh's JSON5 syntax errors (pest): `` --> 2:26``, the line quoted, ``= expected ...``.
_PEST_ERROR = re.compile(r"^\s*-->\s*(\d+):(\d+)\n.*\n\s*= ([^\n]*)$", re.S)
#: Zenoh's type errors: ``JSON error: Message { msg: "...", location: Some(Location { line: 1, column: 9 }) }``.
_SERDE_ERROR = re.compile(r'^JSON error: Message \{ msg: "(.*)", location: '
                          r'(?:Some\(Location \{ line: (\d+), column: (\d+) \}\)|None) \}$', re.S)
#: Longest part of a Zenoh parse error shown (its "expected one of" lists the 23 top-level keys).
_ZENOH_ERROR_MAX_CHARS = 600


def zenoh_config_error_text(exc: BaseException) -> str:
    """Zenoh's refusal of a configuration file as one line, for a user: ``line L, column C:``
    and what it expected, without the quoted source lines and carets of its JSON5 parser or
    the Rust structure around its type errors, and without Rust source paths
    (:func:`zenoh_error_text`)."""
    text = zenoh_error_text(exc)
    if pest := _PEST_ERROR.match(text):
        text = f"line {pest[1]}, column {pest[2]}: {pest[3]}"
    elif serde := _SERDE_ERROR.match(text):
        where = f"line {serde[2]}, column {serde[3]}: " if serde[2] else ""
        text = where + serde[1].replace('\\"', '"').replace("\\\\", "\\")
    elif text.lower().startswith("empty config file"):
        text = "got an empty file"
    text = " ".join(text.split())  # whatever else zenoh says, on one line
    return text if len(text) <= _ZENOH_ERROR_MAX_CHARS else text[:_ZENOH_ERROR_MAX_CHARS - 3] + "..."


def _shown_path(path: str | os.PathLike) -> str:
    """``path`` for a one-line message: as given, or quoted when it holds a newline or another
    unprintable character."""
    text = os.fspath(path)
    return text if text.isprintable() else repr(text)


def _load_zenoh_config(path: str | os.PathLike, label: str) -> zenoh.Config:
    """Zenoh's configuration from the file ``path`` (checked first by
    :func:`zenoh_config_problem`); BusError ``"<label>: ..."`` in one line."""
    if problem := zenoh_config_problem(path):
        raise BusError(f"{label}: {problem}")
    try:
        with open(path, "rb") as f:  # a regular file of at most ZENOH_CONFIG_MAX_BYTES (checked above)
            depth = zenoh_config_depth(f.read(ZENOH_CONFIG_MAX_BYTES + 1))
        if depth > ZENOH_CONFIG_MAX_DEPTH:
            raise BusError(f"{label}: expected a Zenoh configuration nested at most {ZENOH_CONFIG_MAX_DEPTH} deep "
                           f"('{{' and '['), got deeper")
        return zenoh.Config.from_file(os.fspath(path))
    except (zenoh.ZError, OSError, ValueError) as exc:
        raise BusError(f"{label}: expected a readable Zenoh JSON5 configuration: {zenoh_config_error_text(exc)}") from None


@dataclass(frozen=True)
class ZenohConfigText:
    """A Zenoh configuration file as astrodyn read it, once, and checked
    (:func:`read_zenoh_config`).

    A supervisor (``run``, ``serve``, ``replay`` with its live view) writes this text into its
    private work directory (:meth:`write`) and hands every process it starts, and every one
    it restarts, that copy: an edit, a deletion or a FIFO put in place of the user's file
    while the run goes on reaches no process.  ``label`` names the flag and the file in
    messages (``--zenoh-config router.json5``); ``suffix`` is the file's extension, from
    which Zenoh picks the format (.json5, .json, .yaml); ``replaced`` lists the settings of
    the file astrodyn sets itself (:func:`make_config`), for a warning.
    """

    label: str
    suffix: str
    data: bytes = field(repr=False)
    replaced: tuple[str, ...] = ()

    def write(self, folder: str | os.PathLike, name: str = "zenoh-config") -> Path:
        """Write the text to ``folder/<name><suffix>`` (a new file, readable by the user only)
        and return its path; OSError if it cannot be written."""
        path = Path(folder) / f"{name}{self.suffix}"
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_CLOEXEC, 0o600)
        with os.fdopen(fd, "wb") as f:
            f.write(self.data)
        return path

    def warning(self) -> str | None:
        """One line saying which of the file's settings astrodyn replaces, or None."""
        if not self.replaced:
            return None
        return (f"{self.label}: sets {', '.join(self.replaced)}, which astrodyn replaces with its own (mode, endpoints "
                f"and multicast scouting come from the command's flags; docs/security.md)")


def read_zenoh_config(path: str | os.PathLike, flag: str = "--zenoh-config", *, shared: bool = False) -> ZenohConfigText:
    """Read the Zenoh configuration file ``path`` (given with ``flag``) once and check it:
    :func:`zenoh_config_problem` (a regular file of at most :data:`ZENOH_CONFIG_MAX_BYTES`,
    checked again on the open file, so a FIFO put there after the check does not block),
    then Zenoh's own parser on a private copy of the bytes read, the way every process
    parses its copy.  ``shared``: the file is handed to several processes (``run``,
    ``serve``, ``replay``'s live view), so it must not set Zenoh's ``id`` (processes with
    one id never link: a run waited a minute for its logger, then failed).

    BusError ``"<flag> <path>: ..."`` in one line for anything wrong (a bad flag value:
    exit 2 in every command)."""
    label = f"{flag} {_shown_path(path)}"
    if problem := regular_file_problem(path):
        raise BusError(f"{label}: {problem}")
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)  # O_NONBLOCK: a FIFO swapped in opens at once
        with os.fdopen(fd, "rb") as f:
            if problem := _zenoh_config_stat_problem(os.fstat(f.fileno())):
                raise BusError(f"{label}: {problem}")
            data = f.read(ZENOH_CONFIG_MAX_BYTES + 1)
    except OSError as exc:
        raise BusError(f"{label}: expected a readable file, got {exc.strerror or exc}") from None
    if problem := _zenoh_config_size_problem(len(data)):  # it grew after the fstat
        raise BusError(f"{label}: {problem}")
    text = ZenohConfigText(label, Path(path).suffix, data)
    try:
        with tempfile.TemporaryDirectory(prefix="astrodyn-zenoh-config-") as folder:
            config = _load_zenoh_config(text.write(folder), label)
    except OSError as exc:
        raise BusError(f"{label}: cannot check it: no private temporary directory ({exc.strerror or exc})") from None
    if shared and config.get_json("id") != "null":
        raise BusError(f"{label}: sets id {config.get_json('id')}, which every process this command starts would "
                       f"share (Zenoh never links two sessions of one id); remove it")
    default = zenoh.Config()
    replaced = tuple(f"{key.replace('/', '.')} {config.get_json(key)}" for key in _SETTINGS_ASTRODYN_SETS
                     if config.get_json(key) != default.get_json(key)
                     and not (key == "scouting/multicast/enabled" and config.get_json(key) == "false"))
    return ZenohConfigText(label, text.suffix, data, replaced)


def make_config(
    listen: str | Sequence[str] | None = None,
    connect: str | Sequence[str] | None = None,
    mode: str = "peer",
    config_file: str | os.PathLike | None = None,
) -> zenoh.Config:
    """The Zenoh configuration astrodyn uses (see the module docstring for the defaults).

    ``listen=None`` means one loopback endpoint on a free port (ignored in client mode,
    where a session never listens); ``connect`` lists endpoints to join (a router, the
    runner's hub).  Endpoints are Zenoh locators, e.g. ``tcp/127.0.0.1:7447``.
    ``config_file``: a Zenoh JSON5 configuration to start from (TLS certificates under
    ``transport/link/tls``, ``access_control``, ...), checked by :func:`zenoh_config_problem`
    (BusError naming ``--zenoh-config`` and the file, in one line); mode, endpoints and
    scouting are still set from the arguments above, so a session listens only where its
    command says (loopback by default) and multicast scouting stays off whatever the file says.
    """
    if mode not in _MODES:
        raise BusError(f"mode: expected one of {', '.join(_MODES)}, got {mode!r}")
    listen_list = _endpoint_list("listen", listen)
    connect_list = _endpoint_list("connect", connect)
    if listen is None and mode != "client":
        listen_list = [loopback_endpoint()]
    if config_file is not None:
        config = _load_zenoh_config(config_file, f"--zenoh-config {_shown_path(config_file)}")
    else:
        config = zenoh.Config()
    config.insert_json5("mode", json.dumps(mode))
    if mode != "client":
        config.insert_json5("listen/endpoints", json.dumps(listen_list))
    config.insert_json5("connect/endpoints", json.dumps(connect_list))
    config.insert_json5("scouting/multicast/enabled", "false")
    config.insert_json5("scouting/gossip/enabled", "true")
    return config


def open_session(
    listen: str | Sequence[str] | None = None,
    connect: str | Sequence[str] | None = None,
    mode: str = "peer",
    config_file: str | None = None,
) -> zenoh.Session:
    """Open a Zenoh session with astrodyn's defaults; use it as a context manager.

    >>> with open_session(listen=loopback_endpoint(7447)) as hub: ...        # doctest: +SKIP
    >>> with open_session(connect="tcp/127.0.0.1:7447") as child: ...       # doctest: +SKIP

    The first form is the runner's hub; children connect to it and, through gossip, to each
    other.  Raises :class:`BusError` naming the endpoints when Zenoh refuses the config
    (port taken, unreachable ``connect`` endpoint).
    """
    attempts = 3 if listen is None else 1  # only retry ports we picked ourselves
    last: Exception | None = None
    for _ in range(attempts):
        config = make_config(listen, connect, mode, config_file)
        try:
            return zenoh.open(config)
        except zenoh.ZError as exc:
            last = exc
    raise BusError(
        f"cannot open a Zenoh session (mode={mode}, listen={listen!r}, connect={connect!r}): {zenoh_error_text(last)}"
    )


def add_bus_arguments(parser: Any) -> None:
    """Add ``--listen``, ``--connect`` and ``--mode`` to an argparse parser (for services)."""
    parser.add_argument(
        "--listen", action="append", default=None, metavar="ENDPOINT", type=endpoint_argument,
        help="Zenoh endpoint to listen on (repeatable); default tcp/127.0.0.1:<free port>",
    )
    parser.add_argument(
        "--connect", action="append", default=None, metavar="ENDPOINT", type=endpoint_argument,
        help="Zenoh endpoint to connect to (repeatable), e.g. the runner's hub or a router",
    )
    parser.add_argument("--mode", choices=_MODES, default="peer", help="Zenoh mode (default peer)")
    parser.add_argument(
        "--zenoh-config", default=None, metavar="FILE",
        help="Zenoh JSON5 config to start from (TLS, access control); see docs/security.md",
    )


def session_from_args(args: Any) -> zenoh.Session:
    """:func:`open_session` from the options added by :func:`add_bus_arguments`."""
    return open_session(listen=args.listen, connect=args.connect, mode=args.mode,
                        config_file=getattr(args, "zenoh_config", None))


# --------------------------------------------------------------------------- publishing


class _Declared:
    """Mixin: ``close()`` undeclares the Zenoh entity in ``_entity``; usable with ``with``."""

    _entity: Any

    def close(self) -> None:
        self._entity.undeclare()

    def __enter__(self):
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def scenario_keys(scenario: str) -> list[str]:
    """Subscriptions that together receive every put of a scenario (states, batches,
    events, status, heartbeats); needed because ``**`` does not match ``@`` chunks."""
    base = messages.event_key(scenario).rsplit("/", 1)[0]
    return [f"{base}/**", f"{base}/@batch/*", f"{base}/@event", f"{base}/@status", f"{base}/@heartbeat/*"]


def heartbeat_key(scenario: str, process: str) -> str:
    """``astrodyn/<scenario>/@heartbeat/<process>``: application heartbeats of one process.

    (Not a message key of :mod:`astrodyn.messages`: heartbeats are bus-only, never logged.)
    """
    # alive_key validates both names, so heartbeat keys follow the same naming rules
    return messages.alive_key(scenario, process).replace("/@alive/", "/@heartbeat/", 1)


def declare_state_publisher(session: zenoh.Session, key: str) -> zenoh.Publisher:
    """A raw Zenoh publisher for state data: reliable, ``CongestionControl.BLOCK``, JSON."""
    return session.declare_publisher(
        key,
        encoding=zenoh.Encoding.APPLICATION_JSON,
        congestion_control=zenoh.CongestionControl.BLOCK,
        reliability=zenoh.Reliability.RELIABLE,
    )


def signed_put(entity: Any, key: str, payload: bytes, signer: auth.Signer | None) -> None:
    """Put ``payload`` on a declared publisher, with ``signer``'s authenticator as the
    sample's attachment when a signer is given (:mod:`astrodyn.auth`)."""
    if signer is None:
        entity.put(payload)
    else:
        entity.put(payload, attachment=signer.attachment(key, payload))


def process_signer(process: str) -> auth.Signer | None:
    """The signer of a run's child process: the run secret named by
    ``ASTRODYN_RUN_SECRET_FILE`` (:data:`astrodyn.auth.SECRET_ENV`) signs as ``process``;
    None for a process started by hand outside a supervisor.  :class:`BusError` when the
    variable names a file that is missing or not private (mode 0600)."""
    try:
        secret = auth.secret_from_environment()
    except auth.AuthError as exc:
        raise BusError(str(exc)) from None
    return None if secret is None else auth.Signer(secret, process)


class Publisher(_Declared):
    """A state publisher for one channel that stamps the per-channel ``seq`` (0, 1, 2, ...).

    ``publish(msg)`` sets ``msg["seq"]``, encodes with :func:`astrodyn.messages.encode` and
    puts; ``publish_encoded(payload, seq)`` sends a payload already encoded (with its seq),
    e.g. from :func:`astrodyn.messages.encode_orbit_batch`, and checks that ``seq`` is the
    next one.  Reliable delivery, blocking congestion control.  Use as a context manager
    or call :meth:`close`.
    """

    def __init__(self, session: zenoh.Session, key: str, *, first_seq: int = 0, signer: auth.Signer | None = None):
        self.key = key
        self.next_seq = int(first_seq)
        self._entity = declare_state_publisher(session, key)
        self._signer = signer

    @property
    def last_seq(self) -> int | None:
        """The seq of the last message sent (None before the first)."""
        return self.next_seq - 1 if self.next_seq > 0 else None

    def publish(self, msg: dict) -> int:
        seq = self.next_seq
        msg["seq"] = seq
        signed_put(self._entity, self.key, messages.encode(msg), self._signer)
        self.next_seq = seq + 1
        return seq

    def publish_encoded(self, payload: bytes, seq: int) -> None:
        if seq != self.next_seq:
            raise ValueError(f"{self.key}: seq: expected {self.next_seq}, got {seq}")
        signed_put(self._entity, self.key, payload, self._signer)
        self.next_seq = seq + 1

    def matching(self) -> bool:
        """True when at least one subscriber matches this channel."""
        return bool(self._entity.matching_status.matching)  # (the status object itself is always truthy)



class BatchPublisher(_Declared):
    """Publishes many per-body messages as one batch envelope on ``@batch/<process>``.

    The envelope (:func:`astrodyn.messages.encode_batch`) carries ``(key, payload)`` pairs;
    the logger splits it back into per-body channels without re-encoding the payloads, so
    the per-body channel contract holds while the bus carries one sample per step.
    ``last_seq`` tracks the highest seq sent per key (for the end-of-run event).
    """

    def __init__(self, session: zenoh.Session, scenario: str, process: str, *, signer: auth.Signer | None = None):
        self.key = messages.batch_key(scenario, process)
        self.last_seq: dict[str, int] = {}
        self._signer = signer
        self._entity = session.declare_publisher(
            self.key,
            encoding=zenoh.Encoding.APPLICATION_OCTET_STREAM,
            congestion_control=zenoh.CongestionControl.BLOCK,
            reliability=zenoh.Reliability.RELIABLE,
        )

    def publish(self, items: Sequence[tuple[str, bytes]], seqs: Iterable[int] | None = None) -> None:
        """Send ``items`` (key, payload) as one envelope; ``seqs`` (same order) updates ``last_seq``."""
        signed_put(self._entity, self.key, messages.encode_batch(list(items)), self._signer)
        if seqs is not None:
            for (key, _), seq in zip(items, seqs):
                self.last_seq[key] = int(seq)

    def publish_envelope(self, data: bytes) -> None:
        """Send an envelope already framed (:func:`astrodyn.messages.batch_envelope` of the
        compiled encoders' runs: the propagators' hot path)."""
        signed_put(self._entity, self.key, data, self._signer)



#: Event kind a publishing process sends last; its detail is JSON ``{"messages": M}``,
#: the number of state messages the process published (all its channels).
END_EVENT = "stop"


class EventPublisher(_Declared):
    """Publishes ``astrodyn.Event`` messages of one process on ``astrodyn/<scenario>/@event``.

    Each process numbers its own events (seq 0, 1, ...); the logger accounts event seqs
    per (channel, process).  :meth:`end` sends the end-of-run marker: kind
    :data:`END_EVENT` with ``{"messages": M}`` so the logger can tell when it holds every
    state message of the run (see :mod:`astrodyn.service.logger`).
    """

    def __init__(self, session: zenoh.Session, scenario: str, process: str, *, signer: auth.Signer | None = None):
        self.process = messages.check_name(process, "process")
        self.key = messages.event_key(scenario)
        self.next_seq = 0
        self._entity = declare_state_publisher(session, self.key)
        self._signer = signer

    def emit(self, kind: str, t: float, detail: str = "") -> None:
        msg = messages.event_message(t, self.next_seq, self.process, kind, detail)
        signed_put(self._entity, self.key, messages.encode(msg), self._signer)
        self.next_seq += 1

    def end(self, t: float, messages_published: int, **extra: Any) -> None:
        """The end-of-run marker: this process published ``messages_published`` states."""
        detail = {"messages": int(messages_published), **extra}
        self.emit(END_EVENT, t, json.dumps(detail, separators=(",", ":")))


class EventSeqWatcher(_Declared):
    """The event numbering of each process of a scenario, as heard on
    ``astrodyn/<scenario>/@event``: :meth:`next_seq` is one past the highest seq of the
    process's events heard so far (0 for one not heard).  Only events signed by the process
    they name count (``verifier``: the run's, :mod:`astrodyn.auth`), so a forged event never
    moves a number, and memory is one entry per process of the run.  A supervisor gives
    this to a process it restarts when the logger that counted its events is gone itself
    (``serve``'s logger restart: the new logger has seen none of them)."""

    def __init__(self, session: zenoh.Session, scenario: str, *, verifier: auth.Verifier):
        self.verifier = verifier
        self._next: dict[str, int] = {}
        # a ring: never blocks Zenoh's thread when the owner polls late; the newest (highest) seqs are kept
        self._entity = session.declare_subscriber(messages.event_key(scenario), zenoh.handlers.RingChannel(1024))

    def poll(self) -> None:
        while (sample := self._entity.try_recv()) is not None:
            key, payload = str(sample.key_expr), sample.payload.to_bytes()
            try:
                sender = self.verifier.verify(key, payload, _attachment_bytes(sample))
                msg = messages.decode(payload, "event")
            except (auth.AuthError, ValueError):
                continue
            if msg["process"] == sender:
                self._next[sender] = max(self._next.get(sender, 0), int(msg["seq"]) + 1)

    def next_seq(self, process: str) -> int:
        """The seq ``process``'s next event must carry to continue its numbering (after :meth:`poll`)."""
        return self._next.get(process, 0)

    def next_seqs(self) -> dict[str, int]:
        """:meth:`next_seq` of every process heard so far (after :meth:`poll`): process -> seq."""
        return dict(self._next)



# --------------------------------------------------------------------------- liveliness


def declare_alive(session: zenoh.Session, scenario: str, process: str) -> zenoh.LivelinessToken:
    """Declare ``astrodyn/<scenario>/@alive/<process>``; it vanishes when the process dies.

    Keep the returned token referenced for the life of the process (or use it as a context
    manager).  It disappears when the session closes or the process exits or is killed,
    but *not* when the Python code hangs: pair it with a :class:`Heartbeat`.
    """
    return session.liveliness().declare_token(messages.alive_key(scenario, process))


def _process_from_alive_key(key: str) -> str:
    return key.rsplit("/@alive/", 1)[-1]


def alive_processes(session: zenoh.Session, scenario: str, timeout_s: float = 1.0) -> set[str]:
    """The processes whose liveliness token is present now (a liveliness query)."""
    pattern = messages.alive_key(scenario, "x").rsplit("/", 1)[0] + "/*"
    found = set()
    for reply in session.liveliness().get(pattern, timeout=timeout_s):
        if reply.ok is not None:
            found.add(_process_from_alive_key(str(reply.ok.key_expr)))
    return found


def wait_for_process(
    session: zenoh.Session, scenario: str, process: str, timeout_s: float = 10.0
) -> None:
    """Block until ``process``'s liveliness token is visible, or raise :class:`BusError`.

    A process declares its token after its subscribers, and declarations travel in order on
    a link, so once the logger's token is visible its subscriber is too: publish after this.
    """
    deadline = time.monotonic() + timeout_s
    key = messages.alive_key(scenario, process)
    while True:
        for reply in session.liveliness().get(key, timeout=min(1.0, timeout_s)):
            if reply.ok is not None:
                return
        if time.monotonic() >= deadline:
            raise BusError(f"process {process!r} of scenario {scenario!r} not alive after {timeout_s} s")
        time.sleep(0.02)


def wait_for_logger(session: zenoh.Session, scenario: str, process: str = "logger", timeout_s: float = 10.0,
                    verifier: auth.Verifier | None = None) -> None:
    """:func:`wait_for_process` for a run's logger, then, in a run's child (the run secret in
    its environment, :func:`process_signer`), a reply of the logger's ``@latest`` queryable
    signed by ``process`` with the run secret: a liveliness token carries no authenticator,
    and a token forged in the logger's name would otherwise let a propagator publish before
    the real logger subscribes (those samples would be lost).  The queryable is declared
    after the logger's subscribers.  A supervisor passes its own ``verifier`` (it holds the
    secret, not the variable).  :class:`BusError` after ``timeout_s``."""
    deadline = time.monotonic() + timeout_s
    wait_for_process(session, scenario, process, timeout_s)
    if verifier is None:
        try:
            secret = auth.secret_from_environment()
        except auth.AuthError as exc:
            raise BusError(str(exc)) from None
        if secret is None:
            return
        verifier = auth.Verifier(secret)
    key = messages.latest_key(scenario)
    while True:
        for reply in session.get(key, timeout=max(0.05, min(1.0, deadline - time.monotonic())),
                                 target=zenoh.QueryTarget.ALL):
            sample = reply.ok
            if sample is None:
                continue
            try:
                if verifier.verify(str(sample.key_expr), sample.payload.to_bytes(), _attachment_bytes(sample)) == process:
                    return
            except auth.AuthError:
                continue
        if time.monotonic() >= deadline:
            raise BusError(f"process {process!r} of scenario {scenario!r}: no reply signed by the run's {process} "
                           f"after {timeout_s} s (a liveliness token in its name is there)")
        time.sleep(0.02)


class AliveWatcher(_Declared):
    """Tracks which processes of a scenario are alive, from their liveliness tokens.

    ``poll()`` returns the changes since the last call as ``[(process, alive), ...]`` and
    updates ``alive`` (set of names) and ``died`` (name -> monotonic time it vanished).
    With ``history=True`` tokens already present are reported at the first poll.
    Polled, not a callback: call it from the owner's loop.
    """

    def __init__(self, session: zenoh.Session, scenario: str, *, history: bool = True):
        pattern = messages.alive_key(scenario, "x").rsplit("/", 1)[0] + "/*"
        self.alive: set[str] = set()
        self.died: dict[str, float] = {}
        self._entity = session.liveliness().declare_subscriber(
            pattern, zenoh.handlers.FifoChannel(1024), history=history
        )

    def poll(self) -> list[tuple[str, bool]]:
        changes = []
        while (sample := self._entity.try_recv()) is not None:
            process = _process_from_alive_key(str(sample.key_expr))
            is_alive = sample.kind == zenoh.SampleKind.PUT
            if is_alive:
                self.alive.add(process)
                self.died.pop(process, None)
            else:
                self.alive.discard(process)
                self.died[process] = time.monotonic()
            changes.append((process, is_alive))
        return changes



# --------------------------------------------------------------------------- heartbeats


#: Seconds between two heartbeats of a process (:class:`Heartbeat`): at most one per period.
HEARTBEAT_PERIOD_S = 0.5


class Heartbeat(_Declared):
    """Application heartbeat: call :meth:`beat` from the process's main loop.

    At most one message per ``period_s`` (:data:`HEARTBEAT_PERIOD_S`) is sent on ``@heartbeat/<process>`` (JSON: process,
    wall-clock ``time_ns``, a counter ``n`` and any progress fields given, e.g. sim ``t``).
    Because it is driven by the application loop, a hung loop stops the heartbeat even
    though the liveliness token stays alive.
    """

    def __init__(self, session: zenoh.Session, scenario: str, process: str, period_s: float = HEARTBEAT_PERIOD_S, *,
                 signer: auth.Signer | None = None):
        self.process = process
        self.key = heartbeat_key(scenario, process)
        self._signer = signer
        self.period_s = float(period_s)
        self.count = 0
        self._next = 0.0
        # REMOTE: never delivered to this session's own subscribers.  The logger subscribes to
        # @heartbeat/* with a FIFO channel that only its main loop drains; a put delivered to
        # that channel while a flood of forged heartbeats held it full parked the main loop in
        # its own put, for ever (tests/test_bus_fuzz_regressions.py).
        self._entity = session.declare_publisher(self.key, encoding=zenoh.Encoding.APPLICATION_JSON,
                                                 allowed_destination=zenoh.Locality.REMOTE)

    def beat(self, force: bool = False, **progress: Any) -> bool:
        """Send a heartbeat if ``period_s`` has passed (or ``force``); returns whether it sent."""
        now = time.monotonic()
        if not force and now < self._next:
            return False
        self._next = now + self.period_s
        self.count += 1
        body = {"process": self.process, "time_ns": time.time_ns(), "n": self.count, **progress}
        signed_put(self._entity, self.key, json.dumps(body, separators=(",", ":")).encode(), self._signer)
        return True



#: Longest interval between two :meth:`HeartbeatMonitor.poll` calls that counts in full as
#: time spent listening, s.  A longer one (the owner was stopped: Ctrl-Z, SIGSTOP, a paused
#: VM; zenoh's threads in it stopped too, so heartbeats sent meanwhile were never heard)
#: counts as this much only, so a supervisor never judges silence it could not hear.  An
#: owner merely slow (loaded cores) still hears every heartbeat: they wait in the channel.
LISTENING_GAP_S = 1.0


class ListeningClock:
    """Time spent awake, s: monotonic time between reads (:meth:`tick`), each interval
    capped at :data:`LISTENING_GAP_S`.  A process stopped for a while (Ctrl-Z, SIGSTOP, a
    paused container or VM) finds its wall clock far ahead when it resumes, though nothing
    it waits for could have reached it meanwhile (its peers were often stopped with it);
    on this clock the stop counts as :data:`LISTENING_GAP_S` at most.  Deadlines that judge
    another process (silence, an answer due) are measured on it; read it at least once a
    :data:`LISTENING_GAP_S` while waiting, or the waits themselves are undercounted.

    >>> clock = ListeningClock()
    >>> waited = clock.tick()        # seconds awake since the clock was made
    """

    def __init__(self) -> None:
        self.s = 0.0
        self._at = time.monotonic()

    def tick(self, now: float | None = None) -> float:
        """Advance to ``now`` (``time.monotonic()`` by default) and return :attr:`s`."""
        now = time.monotonic() if now is None else now
        self.s += min(max(0.0, now - self._at), LISTENING_GAP_S)
        self._at = now
        return self.s


class HeartbeatMonitor(_Declared):
    """Watches the heartbeats of a scenario; :meth:`stale` lists processes silent too long.

    ``last[process]`` holds the last heartbeat body received (dict) and ``seen[process]``
    the monotonic time it arrived.  Call :meth:`poll` from the owner's loop.  With a
    ``verifier`` (a supervisor's, :mod:`astrodyn.auth`) a heartbeat counts only when it
    carries a valid authenticator of the process it names; ``rejected`` counts the others.

    ``listening_s`` is the owner's listening clock: seconds of monotonic time between
    polls, each interval capped at :data:`LISTENING_GAP_S`; ``heard[process]`` is its
    value at the process's last heartbeat.  Silence measured on it
    (:meth:`astrodyn.service.children.Child.kill_if_stalled`) excludes the time the owner
    itself was stopped (docs/reliability.md: a stopped supervisor).
    """

    def __init__(self, session: zenoh.Session, scenario: str, timeout_s: float = 2.0, *,
                 verifier: auth.Verifier | None = None):
        self.verifier = verifier
        self.rejected = 0
        self.timeout_s = float(timeout_s)
        self.last: dict[str, dict] = {}
        self.seen: dict[str, float] = {}
        self.heard: dict[str, float] = {}
        self.clock = ListeningClock()
        pattern = heartbeat_key(scenario, "x").rsplit("/", 1)[0] + "/*"
        self._entity = session.declare_subscriber(pattern, zenoh.handlers.FifoChannel(1024))

    def poll(self) -> None:
        now = time.monotonic()
        self.clock.tick(now)
        while (sample := self._entity.try_recv()) is not None:
            key = str(sample.key_expr)
            process = key.rsplit("/", 1)[-1]
            payload = sample.payload.to_bytes()
            if self.verifier is not None:
                try:
                    if self.verifier.verify(key, payload, _attachment_bytes(sample)) != process:
                        raise auth.AuthError("bad-mac", "heartbeat signed by another process")
                except auth.AuthError:
                    self.rejected += 1
                    continue
            try:
                body = messages.parse_json(payload)
            except ValueError:
                continue
            self.last[process] = body if isinstance(body, dict) else {}
            self.seen[process] = now
            self.heard[process] = self.listening_s

    @property
    def listening_s(self) -> float:
        """The owner's listening clock (:class:`ListeningClock`) at the last :meth:`poll`."""
        return self.clock.s

    def stale(self, now: float | None = None) -> list[str]:
        """Processes whose last heartbeat is older than ``timeout_s`` (sorted)."""
        self.poll()
        now = time.monotonic() if now is None else now
        return sorted(p for p, seen in self.seen.items() if now - seen > self.timeout_s)



# --------------------------------------------------------------------------- control verbs


@dataclass
class ControlRequest:
    """One control query: ``verb`` and its JSON ``args`` (dict; {} when none were sent).

    Answer exactly once with :meth:`reply` (a JSON-serialisable object) or :meth:`error`.
    A request may be kept and answered later (within the caller's timeout), e.g. ``stop``
    answered once the file is finished.
    """

    verb: str
    args: dict
    key: str
    _query: Any = field(repr=False)
    answered: bool = False

    def reply(self, body: Any) -> None:
        self._query.reply(self.key, json.dumps(body, separators=(",", ":")))
        self._finish()

    def error(self, message: str) -> None:
        self._query.reply_err(json.dumps({"error": message}))
        self._finish()

    def handled_by(self, handle) -> Any:
        """``handle(self)``, answering with an error naming the verb if it raises (and the
        request is still unanswered) instead of letting a request end the server; returns
        what ``handle`` returns, None after an error."""
        try:
            return handle(self)
        except Exception as exc:  # a request the handler did not foresee: its sender learns, the server goes on
            if not self.answered:
                with contextlib.suppress(Exception):
                    self.reply({"error": f"{self.verb}: could not be handled: {type(exc).__name__}: {str(exc)[:200]}"})
            return None

    def _finish(self) -> None:
        self.answered = True
        self._query.drop()


def _parse_query_args(query: Any) -> dict:
    args: dict = {}
    for name, value in query.parameters:
        args[name] = value
    payload = query.payload
    if payload is not None and len(payload):
        try:
            body = messages.parse_json(payload.to_bytes(), finite=True)
        except ValueError as exc:
            raise ValueError(f"payload: expected a JSON object, got invalid JSON ({exc})") from None
        if not isinstance(body, dict):
            raise ValueError(f"payload: expected a JSON object, got {type(body).__name__}")
        args.update(body)
    return args


#: Real-time factors a ``rate`` verb may set (both ends included); "inf" is also accepted
#: by ``serve`` (as fast as possible).
RATE_BOUNDS = (1e-3, 1e6)


def parse_rate_factor(raw: Any) -> float:
    """The real-time factor of a ``rate`` verb: a number within :data:`RATE_BOUNDS` or
    ``"inf"`` (as fast as possible); ``ValueError`` naming the allowed range otherwise."""
    if raw == "inf" or raw == math.inf:
        return math.inf
    factor = math.nan
    if type(raw) in (int, float):  # a JSON number (not a bool, not a numeric string)
        try:
            factor = float(raw)
        except OverflowError:  # an integer beyond float64
            pass
    if RATE_BOUNDS[0] <= factor <= RATE_BOUNDS[1]:
        return factor
    shown = repr(raw)
    shown = shown if len(shown) <= 40 else shown[:37] + "..."
    raise ValueError(f'rate: expected {{"factor": x}} with {RATE_BOUNDS[0]:g} <= x <= {RATE_BOUNDS[1]:g} '
                     f'or "inf", got {shown}')


def rate_argument(text: str) -> float:
    """argparse ``type`` of a ``--rate`` option: the word ``inf`` (as fast as possible) or a
    number spelled within :data:`RATE_BOUNDS` (``1e400``, which float() reads as inf, and
    ``nan`` are refused like any number outside them)."""
    text = str(text)
    try:  # the number spelled; "inf" only as the word (float() also reads 1e400 as inf)
        value = math.inf if text.strip() == "inf" else float(text)
    except ValueError:
        value = math.nan
    if math.isinf(value) and text.strip() != "inf":
        value = math.nan
    try:
        return parse_rate_factor(value)  # the one check of the bounds
    except ValueError:
        shown = repr(text) if len(repr(text)) <= 40 else repr(text)[:37] + "..."
        raise argparse.ArgumentTypeError(f"expected a real-time factor with {RATE_BOUNDS[0]:g} <= x <= "
                                         f'{RATE_BOUNDS[1]:g} or "inf", got {shown}') from None


class ControlServer(_Declared):
    """Queryables for control verbs on ``astrodyn/<scenario>/@control/<verb>``.

    ``poll()`` returns pending :class:`ControlRequest` objects (FIFO handlers, so the owner
    handles them in its own loop and thread).  ``extra_keys`` adds queryables on other keys
    (e.g. the logger's ``@status``); their requests carry the last key segment as verb.

    ``token``: the run's control token (:mod:`astrodyn.auth`); a query that does not carry
    it in its attachment is answered with an error naming the verb and never reaches
    ``poll()``; ``rejected`` counts such queries per verb.  ``token=None`` serves every
    query (``--open-control``, or a supervisor's private queryables).

    ``answer_unknown``: also answer a query for any other verb of the scenario
    (``@control/<verb>``) with an error naming the verbs served (``{"error": "seek: unknown
    control verb; this process answers status, pause, ..."}``), never passed to ``poll()``;
    without it such a query finds no queryable and its sender gets no reply at all
    (:func:`send_control` returns ``[]``).  None (the default): when ``verbs`` holds every
    one of :data:`CONTROL_VERBS`, i.e. for the process that runs the scenario (``serve``,
    ``replay``), not for one that serves a verb or two beside it (the logger's ``stop``).

    A verb acts only on a query of exactly its own key (``astrodyn/demo/@control/pause``).
    Any other key expression that reaches it (``astrodyn/demo/@control/*``, the key serve
    prints as ``control``, ``.../@control/**``, ``astrodyn/*/@control/stop``, ``.../st*``)
    is never passed to ``poll()``: with ``answer_unknown`` it gets one error reply (from
    the ``@control/*`` catch-all, not one per verb) naming the verbs and saying to query one
    verb's key; nothing is done.  Before, each verb's queryable answered it, so one query
    of the advertised key paused, resumed and stopped the service at once (svc probe F4).
    The ``extra_keys`` (read-only status) still answer any query that reaches them.
    """

    def __init__(
        self,
        session: zenoh.Session,
        scenario: str,
        verbs: Iterable[str] = CONTROL_VERBS,
        extra_keys: Mapping[str, str] | None = None,
        *,
        token: str | None = None,
        answer_unknown: bool | None = None,
    ):
        self.token = token
        self.rejected: dict[str, int] = {}
        self.verbs = tuple(verbs)
        keys = {messages.control_key(scenario, verb): verb for verb in self.verbs}
        self._verb_keys = frozenset(keys)  # a query acts on one of these only if its key expression is exactly it
        keys.update(extra_keys or {})
        self._queryables = [
            (key, verb, session.declare_queryable(key, zenoh.handlers.FifoChannel(256)))
            for key, verb in keys.items()
        ]
        if answer_unknown is None:
            answer_unknown = set(CONTROL_VERBS) <= set(self.verbs)
        self._control_prefix = messages.control_key(scenario, "x").rsplit("/", 1)[0] + "/"  # astrodyn/<scenario>/@control/
        self._any_verb = None  # a queryable on @control/*: a verb this server lacks or a wildcard gets an error, not silence
        if answer_unknown:
            self._any_verb = session.declare_queryable(self._control_prefix + "*", zenoh.handlers.FifoChannel(256))

    def poll(self) -> list[ControlRequest]:
        self._answer_unknown_verbs()
        requests = []
        for key, verb, queryable in self._queryables:
            while (query := queryable.try_recv()) is not None:
                if key in self._verb_keys and str(query.key_expr) != key:
                    # a wildcard or any expression other than this verb's key: never an action
                    # (the @control/* catch-all answers it once, _answer_unknown_verbs)
                    query.drop()
                    continue
                if self.token is not None and not auth.token_matches(
                        self.token, auth.token_from_attachment(_attachment_bytes(query))):
                    self.rejected[verb] = self.rejected.get(verb, 0) + 1
                    query.reply_err(json.dumps({"error": f"{verb}: unauthorised: this run's control verbs need its "
                                                         "control token (docs/security.md)"}))
                    query.drop()
                    continue
                try:
                    args = _parse_query_args(query)
                except ValueError as exc:
                    query.reply_err(json.dumps({"error": f"{verb}: {exc}"}))
                    query.drop()
                    continue
                requests.append(ControlRequest(verb, args, key, query))
        return requests

    def _answer_unknown_verbs(self) -> None:
        """Answer each pending query on ``@control/*`` that is not exactly a served verb's
        key, once: a single verb this server does not serve gets an error naming the verbs it
        does; any other expression (a wildcard: ``@control/*``, ``**``, ``st*``; another
        scenario's keys too) an error naming them and saying to query one verb's key.  A
        served verb's own key is dropped here: its queryable answers it."""
        if self._any_verb is None:
            return
        verbs = ", ".join(self.verbs)
        while (query := self._any_verb.try_recv()) is not None:
            expr = str(query.key_expr)
            verb = expr[len(self._control_prefix):] if expr.startswith(self._control_prefix) else ""
            if expr in self._verb_keys:
                message = None
            elif verb and not any(c in verb for c in "/*$"):
                shown = verb if len(verb) <= 40 else verb[:37] + "..."
                message = f"{shown}: unknown control verb; this process answers {verbs}"
            else:
                shown = expr if len(expr) <= 80 else expr[:77] + "..."
                message = (f"{shown}: not the key of one control verb, so nothing was done; query one verb's key, "
                           f"{self._control_prefix}<verb>, with <verb> one of {verbs}")
            if message is not None:
                with contextlib.suppress(Exception):  # the querier may be gone: never the server's concern
                    query.reply_err(json.dumps({"error": message}))
            query.drop()

    def close(self) -> None:
        for _, _, queryable in self._queryables:
            queryable.undeclare()
        if self._any_verb is not None:
            self._any_verb.undeclare()


class SchemaServer(_Declared):
    """Answers queries on ``astrodyn/<scenario>/@schema/<kind>`` with the JSON Schema of each
    message kind (:data:`astrodyn.messages.SCHEMAS`), so a client with no astrodyn code can
    learn the message layout from the bus: ``session.get("astrodyn/demo/@schema/*")`` gets
    one reply per kind, keyed by its kind.  Answered on Zenoh's thread (a fixed reply, no
    state), open to anyone on the bus like the states themselves."""

    def __init__(self, session: zenoh.Session, scenario: str):
        self._replies = [(zenoh.KeyExpr(messages.schema_key(scenario, kind)), json.dumps(messages.json_schema(t)).encode())
                         for kind, t in messages.MESSAGE_TYPES.items()]
        base = messages.schema_key(scenario, "orbit").rsplit("/", 1)[0]
        self._entity = session.declare_queryable(f"{base}/*", self._answer)

    def _answer(self, query) -> None:
        for key, payload in self._replies:
            if key.intersects(query.key_expr):
                query.reply(key, payload, encoding=zenoh.Encoding.APPLICATION_JSON)


def _attachment_bytes(obj: Any) -> bytes | None:
    a = obj.attachment
    return None if a is None else a.to_bytes()


def query_json(
    session: zenoh.Session, key: str, args: Mapping[str, Any] | None = None, timeout_s: float = 5.0,
    token: str | None = None,
) -> list[dict]:
    """Query ``key`` (all matching queryables) and return the JSON replies.

    An error reply becomes ``{"error": ...}``; no replies within ``timeout_s`` gives [].
    ``token``: a control token to present (:func:`astrodyn.auth.token_attachment`).
    """
    payload = json.dumps(dict(args)) if args else None
    replies = []
    handler = session.get(
        key, target=zenoh.QueryTarget.ALL, payload=payload, timeout=timeout_s,
        consolidation=zenoh.QueryConsolidation(zenoh.ConsolidationMode.NONE),
        attachment=None if token is None else auth.token_attachment(token),
    )
    for reply in handler:
        sample = reply.ok
        raw = sample.payload.to_bytes() if sample is not None else reply.err.payload.to_bytes()
        try:
            body = messages.parse_json(raw)
        except ValueError:
            body = {"error": raw.decode("utf-8", "replace")[:200]}
        if sample is None and not (isinstance(body, dict) and "error" in body):
            body = {"error": body}
        replies.append(body if isinstance(body, dict) else {"value": body})
    return replies


def send_control(
    session: zenoh.Session, scenario: str, verb: str, args: Mapping[str, Any] | None = None,
    timeout_s: float = 5.0, token: str | None = None, *, require_reply: bool = False,
) -> list[dict]:
    """Send a control verb (``status``, ``pause``, ``resume``, ``rate``, ``stop``; ``seek`` of
    ``replay``, ``fault`` of a closed-loop ``serve``) to a scenario.

    ``rate`` takes ``{"factor": 2.0}``.  Returns every answering process's JSON reply, a
    list: one dict per process that answered within ``timeout_s`` seconds (usually one:
    ``serve`` or ``replay``).  A refusal is a reply too: ``{"error": "..."}`` names what is
    wrong (a bad argument, a missing or wrong token: ``...unauthorised...``, a verb the
    process does not have: ``...unknown control verb; this process answers status, ...``).
    ``token``: the run's control token (printed by ``serve``, stored in its 0600 token
    file).

    ``[]`` means that nothing answered: no process of ``scenario`` is reachable from
    ``session`` (a wrong hub endpoint or scenario name, a run that has ended) or none
    answered within ``timeout_s``.  With ``require_reply=True`` that is a :class:`BusError`
    naming the scenario, the verb and what to check, instead of ``[]``.
    """
    replies = query_json(session, messages.control_key(scenario, verb), args, timeout_s, token=token)
    if not replies and require_reply:
        raise BusError(f"control verb {verb!r}: no process of scenario {scenario!r} answered within {timeout_s:g} s "
                       f"on {messages.control_key(scenario, verb)}; check the hub endpoint the session connects to "
                       f"(the \"hub\" of serve's first stdout line) and the scenario name, and that the run still goes on")
    return replies


# --------------------------------------------------------------------------- consumers


def state_samples(key: str, payload: bytes) -> list[tuple[str, bytes]]:
    """The per-body ``(key, payload)`` pairs a received sample carries.

    Small scenes publish one sample per body on its own key; large ones (and ``replay
    --batch``) publish one envelope per instant on ``astrodyn/<scenario>/@batch/<kind>``.
    A consumer subscribed to both ``astrodyn/<scenario>/**`` and
    ``astrodyn/<scenario>/@batch/*`` reads either form alike through this function
    (``MessageError`` for a damaged envelope)::

        for key, payload in bus.state_samples(str(sample.key_expr), sample.payload.to_bytes()):
            msg = messages.decode(payload, key)
    """
    if "/@batch/" in key:
        return messages.decode_batch(payload)
    return [(key, payload)]
