"""Who may talk to the viewer, and how it says no (docs/reliability.md, "The viewer's host and origin checks").

:class:`Guard` is the app's outermost middleware of its own (inside Starlette's last-resort error
middleware), so it sees every request before any route, the page and the static files included:

* **the Host header** must name the viewer: a loopback name (:data:`LOOPBACK`), the address it was
  told to bind (unless that is loopback already) or a name given with ``--allow-host``; any port
  (an SSH tunnel serves the viewer on another one). Anything else is 421 Misdirected Request. A
  page of another site that rebinds its own name to 127.0.0.1 (DNS rebinding) sends its own name
  as the Host, so it reads nothing and starts nothing;
* **a write** (POST, PUT, PATCH, DELETE) that a browser sends from another origin is 403: its
  ``Origin`` (else its ``Referer``) must be the viewer's own (the scheme, the Host's name and
  port), and ``Sec-Fetch-Site`` must say ``same-origin`` (or ``none``). A client that sends none
  of them (curl, scripts, TestClient) is not a browser page and goes on;
* **a bug**: an exception that nothing else answered is logged (logger ``billiards.web``, with its
  traceback) and answered 500 with a generic sentence: no traceback and no exception text reaches
  the client.

Every error the viewer answers has one shape, ``{"error": "<one sentence>"}`` (:func:`error`).
"""

from __future__ import annotations

import ipaddress
import logging
import re
from collections.abc import Iterable
from http import HTTPStatus
from urllib.parse import urlsplit

from fastapi.responses import JSONResponse

LOOPBACK = ("localhost", "127.0.0.1", "::1")
WRITES = frozenset({"POST", "PUT", "PATCH", "DELETE"})
SAME_SITE = frozenset({"same-origin", "none"})  # Sec-Fetch-Site values of the viewer's own page (none: the user's own action)
DEFAULT_PORTS = {"http": 80, "https": 443, "ws": 80, "wss": 443}
BUG = "the viewer failed to answer this request (a bug: the server's log holds the traceback); it goes on serving"
# a Host header (RFC 9110: uri-host [":" port]): a bracketed IPv6 address or a registered name / IPv4 address; nothing else
# (no user info, no path, no spaces), so that what is compared is what the browser sent
_HOST = re.compile(r"(?:\[(?P<v6>[0-9a-f:.]+)\]|(?P<name>[a-z0-9._~-]+))(?::(?P<port>[0-9]{0,5}))?")
_ORIGIN = re.compile(r"(?P<scheme>[a-z][a-z0-9+.-]*)://(?P<host>[^/?#@\s]+)")
log = logging.getLogger("billiards.web")


def error(status: int, message: str, headers: dict | None = None) -> JSONResponse:
    """The viewer's one error shape: ``{"error": message}`` with ``status``."""
    return JSONResponse({"error": message}, status_code=int(status), headers=headers)


def _canonical(name: str) -> str:
    """A host name in lower case; an IP address in its one spelling (``0:0::1`` is ``::1``)."""
    name = name.strip().lower()
    try:
        return str(ipaddress.ip_address(name))
    except ValueError:
        return name


def parse_host(value: str) -> tuple[str, int | None] | None:
    """(name, port or None) of a Host header's value, the name canonical; None: not a host."""
    m = _HOST.fullmatch(value.strip().lower())
    if m is None:
        return None
    if m["v6"] is not None:
        try:
            name = str(ipaddress.IPv6Address(m["v6"]))
        except ValueError:
            return None
    else:
        name = _canonical(m["name"])
    port = m["port"]
    if port == "" or (port is not None and int(port) > 65535):
        return None
    return name, int(port) if port else None


def host_names(names: Iterable[str] = ()) -> tuple[str, ...]:
    """The names the viewer answers: the loopback ones, then ``names`` (a bind address, ``--allow-host``
    values: a name or an address, IPv6 with or without brackets, no port). A name that is not one
    raises ValueError."""
    out = list(LOOPBACK)
    for raw in names:
        text = str(raw).strip()
        bare = text[1:-1] if text.startswith("[") and text.endswith("]") else text
        parsed = parse_host(f"[{bare}]" if ":" in bare else bare)
        if not text or parsed is None or parsed[1] is not None:
            raise ValueError(f"{raw!r} is not a host name or address (a name such as viewer.lan, or an address such as 192.168.1.5 "
                             f"or fe80::1, without a port)")
        if parsed[0] not in out:
            out.append(parsed[0])
    return tuple(out)


def _shown(name: str) -> str:
    return f"[{name}]" if ":" in name else name


def _quoted(value: str, limit: int = 120) -> str:
    return repr(value if len(value) <= limit else value[:limit] + "...")


class Guard:
    """The ASGI middleware of the module's docstring: ``hosts`` are the names the viewer answers
    (:func:`host_names`)."""

    def __init__(self, app, hosts: Iterable[str] = LOOPBACK):
        self.app = app
        self.hosts = frozenset(_canonical(h) for h in hosts)
        self.listed = ", ".join(_shown(h) for h in hosts)

    async def __call__(self, scope, receive, send):
        if scope["type"] not in ("http", "websocket"):
            await self.app(scope, receive, send)
            return
        refusal = self.refusal(scope)
        if refusal is not None:
            if scope["type"] == "websocket":
                await send({"type": "websocket.close", "code": 1008, "reason": refusal[1][:120]})
            else:
                await error(*refusal)(scope, receive, send)
            return
        if scope["type"] == "websocket":
            await self.app(scope, receive, send)
            return
        started = False

        async def sending(message):
            nonlocal started
            started = started or message["type"] == "http.response.start"
            await send(message)

        try:
            await self.app(scope, receive, sending)
        except Exception:
            if started:  # half an answer is out: the server closes the connection and logs it
                raise
            log.exception("the viewer failed on %s %s", scope.get("method"), scope.get("path"))
            await error(HTTPStatus.INTERNAL_SERVER_ERROR, BUG)(scope, receive, send)

    # ------------------------------------------------------------------------- the checks

    def refusal(self, scope) -> tuple[int, str] | None:
        """(status, sentence) for a request the viewer does not answer; None: it answers it."""
        headers = [(k.lower(), v.decode("latin-1")) for k, v in scope.get("headers", ())]
        hosts = [v for k, v in headers if k == b"host"]
        if len(hosts) != 1:
            return HTTPStatus.BAD_REQUEST, ("the request has no Host header" if not hosts else "the request has more than one Host header")
        host = parse_host(hosts[0])
        if host is None or host[0] not in self.hosts:
            return (HTTPStatus.MISDIRECTED_REQUEST,
                    f"Host {_quoted(hosts[0])} is not one of this viewer's names ({self.listed}): refused, so that another site's "
                    f"page cannot reach the viewer by pointing its own name at this machine (DNS rebinding); "
                    f"python -m billiards.web --allow-host NAME adds a name")
        if scope["type"] == "http" and scope.get("method", "GET").upper() not in WRITES:
            return None
        scheme = scope.get("scheme", "http")
        own = (scheme, host[0], host[1] if host[1] is not None else DEFAULT_PORTS.get(scheme))
        field = dict(headers)
        origin, referer, site = field.get(b"origin"), field.get(b"referer"), field.get(b"sec-fetch-site")
        said = None
        if origin is not None:
            said = ("Origin", origin, origin)
        elif referer is not None:
            parts = urlsplit(referer.strip())
            said = ("Referer", referer, f"{parts.scheme}://{parts.netloc}")
        if said is not None and self._origin(said[2]) != own:
            return (HTTPStatus.FORBIDDEN,
                    f"a write from another origin ({said[0]} {_quoted(said[1])}) is refused: only the viewer's own page "
                    f"({scheme}://{hosts[0].strip()}) may play shots, ask agents or start matches")
        if site is not None and site.strip().lower() not in SAME_SITE:
            return (HTTPStatus.FORBIDDEN,
                    f"a write from another site (Sec-Fetch-Site {_quoted(site)}) is refused: only the viewer's own page "
                    f"({scheme}://{hosts[0].strip()}) may play shots, ask agents or start matches")
        return None

    @staticmethod
    def _origin(value: str) -> tuple[str, str, int | None] | None:
        """(scheme, host name, port) of an origin (``scheme://host[:port]``); None: not one (``null``, a path, user info)."""
        m = _ORIGIN.fullmatch(value.strip().lower())
        if m is None:
            return None
        host = parse_host(m["host"])
        if host is None:
            return None
        scheme = m["scheme"]
        return scheme, host[0], host[1] if host[1] is not None else DEFAULT_PORTS.get(scheme)


__all__ = ["BUG", "LOOPBACK", "Guard", "error", "host_names", "parse_host"]
