"""``funicular serve``: the interactive explorer, a local web application in the browser."""

from __future__ import annotations

import argparse
import importlib.util
import socket
import sys
import webbrowser

from funicular._extras import install_command
from funicular.cli._common import EXIT_BAD_INPUT, EXIT_OK, add_scenario_name, integer

DEFAULT_PORT = 8765


def _port(text: str) -> int:
    value = integer(text)
    if not 0 <= value <= 65535:
        raise argparse.ArgumentTypeError(f"{value} is not a port; give 1 to 65535, or 0 for any free port")
    return value


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_scenario_name(parser)
    parser.add_argument(
        "--port", type=_port, default=DEFAULT_PORT, help=f"port to listen on (default {DEFAULT_PORT}; 0: any free port)"
    )
    parser.add_argument(
        "--host",
        default="127.0.0.1",
        help="address to listen on (default 127.0.0.1: this machine only; the explorer has no login)",
    )
    parser.add_argument("--open", action="store_true", help="open the page in the default web browser")


def run(args: argparse.Namespace) -> int:
    missing = [name for name in ("starlette", "uvicorn") if importlib.util.find_spec(name) is None]
    if missing:
        print(
            f"funicular: error: the explorer needs the serve extra (missing: {', '.join(missing)}); install it "
            f"with {install_command('serve')}.",
            file=sys.stderr,
        )
        return EXIT_BAD_INPUT
    import uvicorn  # (only here: the extra is optional)

    from funicular.explorer._app import create_app
    from funicular.explorer._state import state_of_scenario

    app = create_app(state_of_scenario(args.scenario), args.scenario)
    # The socket is bound here, so that a busy port is one sentence and --port 0's port can be shown.
    try:
        listener = socket.create_server((args.host, args.port))
    except OSError as error:
        print(
            f"funicular: error: cannot listen on {args.host}:{args.port}: {error.strerror or error}.", file=sys.stderr
        )
        return EXIT_BAD_INPUT
    # Connections accepted from a socket made this way get no TCP_NODELAY from asyncio (its protocol
    # number is 0, not IPPROTO_TCP): without it, a response's body waits for the browser's delayed
    # acknowledgement of its headers, about 40 ms per solve. Accepted sockets inherit it from here.
    listener.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    host, port = listener.getsockname()[:2]
    url = f"http://{f'[{host}]' if ':' in host else host}:{port}/"
    print(f"funicular explorer at {url} (Ctrl-C stops it)", flush=True)
    if args.open:
        webbrowser.open(url)
    server = uvicorn.Server(uvicorn.Config(app, log_level="warning", access_log=False))
    server.run(sockets=[listener])
    return EXIT_OK
