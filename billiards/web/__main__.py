"""``python -m billiards.web [--host 127.0.0.1] [--port 0] [--allow-host NAME ...] [--out outputs/web] [RUN_DIR ...]``:
serve the viewer; prints its URL on one line (port 0, the default: a free port). It answers only
the loopback names, the ``--host`` address and the ``--allow-host`` names (docs/reliability.md)."""

from __future__ import annotations

import argparse
import socket
import sys
from pathlib import Path


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m billiards.web",
                                     description="Serve the viewer (docs/viewer.md): replays of runs, the shot lab, matches "
                                                 "against the agents. Prints its URL on one line.")
    parser.add_argument("run_dirs", nargs="*", type=Path, help="run directories to offer in the replay view, besides results/")
    parser.add_argument("--host", default="127.0.0.1", help="address to bind (default 127.0.0.1: this machine only)")
    parser.add_argument("--port", type=int, default=0, help="port (default 0: a free one)")
    parser.add_argument("--allow-host", action="append", default=[], metavar="NAME",
                        help="a host name or address the browser uses to reach the viewer, besides localhost, 127.0.0.1, [::1] "
                             "and the --host address (repeatable; any other Host is refused: DNS rebinding)")
    parser.add_argument("--out", type=Path, default=None, help="where played matches are saved (default outputs/web)")
    parser.add_argument("--threads", type=int, default=1, help="threads of the simulator's batches and the networks (default 1)")
    args = parser.parse_args(argv)
    for d in args.run_dirs:
        if not d.is_dir():
            parser.error(f"{d} is not a directory")
    if not 0 <= args.port <= 65535:
        parser.error(f"--port must lie in 0..65535, got {args.port}")

    import uvicorn

    from billiards.device import set_threads

    from .app import DEFAULT_OUT, create_app
    from .guard import host_names

    try:
        hosts = host_names([args.host, *args.allow_host])
    except ValueError as err:
        parser.error(f"--host / --allow-host: {err}")
    set_threads(args.threads)
    app = create_app(run_dirs=args.run_dirs, out_dir=args.out or DEFAULT_OUT, hosts=hosts)
    family = socket.AF_INET6 if ":" in args.host else socket.AF_INET
    # proto IPPROTO_TCP, not 0: asyncio sets TCP_NODELAY only on sockets that say they are TCP, and without it a
    # kept-alive connection waits ~40 ms per answer (Nagle's algorithm against the client's delayed ACK)
    sock = socket.socket(family, socket.SOCK_STREAM, socket.IPPROTO_TCP)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind((args.host, args.port))
    except OSError as err:
        print(f"Error: cannot listen on {args.host}:{args.port}: {err.strerror}", file=sys.stderr)
        return 2
    sock.listen(2048)  # connections wait in the backlog until the server accepts them
    host, port = sock.getsockname()[:2]
    shown = f"[{host}]" if ":" in host else host
    print(f"billiards viewer: http://{shown}:{port}/", flush=True)
    if host in ("0.0.0.0", "::") and not args.allow_host:
        print(f"note: the viewer answers only the Host names {', '.join(f'[{h}]' if ':' in h else h for h in hosts)}; "
              f"give the name or address other machines use with --allow-host", file=sys.stderr, flush=True)
    server = uvicorn.Server(uvicorn.Config(app, log_level="warning"))
    server.run(sockets=[sock])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
