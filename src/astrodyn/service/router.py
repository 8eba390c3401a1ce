"""``astrodyn router``: a Zenoh router, so astrodyn processes on several hosts meet.

    astrodyn router                                 # tcp/127.0.0.1:7447 (this machine only)
    astrodyn router --listen tcp/0.0.0.0:7447       # open to the network (prints a warning)

A router is a Zenoh session in ``router`` mode (:func:`astrodyn.bus.open_session` with
``mode="router"``, multicast scouting off): clients and peers that ``--connect`` to it
exchange publications, queries and liveliness tokens through it, so each process needs to
know only the router's endpoint.  ``astrodyn run CONFIG --connect tcp/HOST:7447``, the
services (``services/orbit.py`` ... with ``--mode client --connect tcp/HOST:7447``) and
``astrodyn serve`` join it.  Two-host walk-through, TLS and access control:
``docs/multihost.md``.

The default endpoint is loopback; listening on every interface (``0.0.0.0``, ``[::]``)
happens only when asked and prints a warning, because Zenoh traffic is neither encrypted
nor authenticated unless TLS and access control are configured (``--config`` takes a
Zenoh JSON5 config file for that, at most :data:`astrodyn.bus.ZENOH_CONFIG_MAX_BYTES`).
As for every astrodyn session, the endpoints and scouting come from the flags, never from
the file: a file's ``listen`` / ``connect`` endpoints or multicast scouting are replaced
(with a warning naming them).  Before, ``--config`` without ``--listen`` left the file's
endpoints, or Zenoh's default ``tcp/[::]:7447`` on every interface, and multicast
scouting on.

It runs until SIGTERM or Ctrl-C (exit 0); with ``--status-interval S`` it prints the
routers and peers connected every S seconds.  Exit 2 on bad arguments (a ``--config``
that is not a regular file, is too large or is not a Zenoh configuration included), 1 if the
session cannot be opened (port taken, a TLS file the config names cannot be read).
"""

from __future__ import annotations

import argparse
import json
import sys
import threading
import time

__all__ = ["DEFAULT_LISTEN", "main", "open_router", "is_wildcard"]

DEFAULT_LISTEN = "tcp/127.0.0.1:7447"
_WILDCARD_HOSTS = ("0.0.0.0", "[::]", "::", "[::0]")


def is_wildcard(endpoint: str) -> bool:
    """True when ``endpoint`` (``proto/host:port``) binds every interface."""
    try:
        host = endpoint.split("/", 1)[1].rsplit(":", 1)[0]
    except IndexError:
        return False
    return host in _WILDCARD_HOSTS


def open_router(listen: list[str], connect: list[str] | None = None, config=None):
    """Open a Zenoh session in router mode with astrodyn's defaults: ``listen`` endpoints only
    (never the file's, nor Zenoh's default ``tcp/[::]:7447``, which binds every interface),
    ``connect`` ones, multicast scouting off (:func:`astrodyn.bus.make_config`), on top of
    ``config`` (a :class:`astrodyn.bus.ZenohConfigText`, the ``--config`` file as read and
    checked once, or None).  BusError if the session cannot be opened (port taken, a TLS file
    the config names cannot be read)."""
    import tempfile

    from astrodyn import bus

    if config is None:
        return bus.open_session(listen=listen, connect=connect or None, mode="router")
    with tempfile.TemporaryDirectory(prefix="astrodyn-router-") as folder:  # Zenoh reads its config from a file
        try:
            copy = config.write(folder)
        except OSError as exc:
            raise bus.BusError(f"{config.label}: cannot copy it for Zenoh: {exc.strerror or exc}") from None
        try:
            return bus.open_session(listen=listen, connect=connect or None, mode="router", config_file=copy)
        except bus.BusError as exc:  # named after the file the user gave, not the private copy
            raise bus.BusError(f"{exc} ({config.label})") from None


def main(argv: list[str] | None = None) -> int:
    from astrodyn import bus
    from astrodyn.service.children import wall_seconds
    from astrodyn.signals import catch_stop_signals

    ap = argparse.ArgumentParser(prog="astrodyn router", description=__doc__.split("\n\n")[0])
    ap.add_argument("--listen", action="append", default=None, metavar="ENDPOINT", type=bus.endpoint_argument,
                    help=f"endpoint to listen on (repeatable; default {DEFAULT_LISTEN}); tcp/0.0.0.0:7447 opens it to the network")
    ap.add_argument("--connect", action="append", default=None, metavar="ENDPOINT", type=bus.endpoint_argument,
                    help="another router to join (repeatable), for a mesh of routers")
    ap.add_argument("--config", metavar="FILE",
                    help="a Zenoh JSON5 config (TLS, access control), at most 1 MiB; endpoints come from --listen / "
                         "--connect and multicast scouting stays off whatever it says (docs/multihost.md)")
    ap.add_argument("--status-interval", type=lambda text: wall_seconds(text, zero=True), default=0.0, metavar="S",
                    help="print the connected routers and peers every S wall seconds (0, the default: never)")
    args = ap.parse_args(argv)
    listen = args.listen or [DEFAULT_LISTEN]
    try:
        for e in listen:
            bus.make_config(listen=[e], mode="router")  # the endpoints together, as zenoh takes them
        config = None if args.config is None else bus.read_zenoh_config(args.config, "--config")
    except bus.BusError as exc:  # a bad flag value: exit 2, as argparse's own refusals
        print(f"astrodyn router: {exc}", file=sys.stderr)
        return 2
    if config is not None and (warning := config.warning()):
        print(f"astrodyn router: warning: {warning}", file=sys.stderr)
    for e in listen:
        if is_wildcard(e):
            print(f"astrodyn router: WARNING: {e} listens on every network interface; Zenoh traffic is not encrypted or "
                  "authenticated unless TLS and access control are configured (docs/multihost.md)", file=sys.stderr)
    stop = threading.Event()
    catch_stop_signals(lambda why: stop.set())
    try:
        session = open_router(listen, args.connect, config)
    except bus.BusError as exc:
        print(f"astrodyn router: {exc}", file=sys.stderr)
        return 1
    with session:
        print(json.dumps({"router": str(session.info.zid()), "listen": listen, "connect": args.connect or []}),
              flush=True)
        next_status = time.monotonic() + args.status_interval
        while not stop.wait(0.2):
            if args.status_interval > 0 and time.monotonic() >= next_status:
                next_status += args.status_interval
                routers = [str(z) for z in session.info.routers_zid()]
                peers = [str(z) for z in session.info.peers_zid()]
                print(f"astrodyn router: {len(routers)} routers, {len(peers)} peers connected", file=sys.stderr, flush=True)
    print("astrodyn router: stopped", file=sys.stderr, flush=True)
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
