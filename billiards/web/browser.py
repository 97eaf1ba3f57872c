"""Headless Chromium for the viewer's browser tests and screenshots (tests/web/test_web_browser.py,
benchmarks/web_screenshots.py): where the binary is, how it is started, and the app served by
uvicorn in a thread of this process. Playwright is imported by the callers, not here."""

from __future__ import annotations

import contextlib
import shutil
import socket
import threading
import time
from pathlib import Path

CHROMIUM_ARGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking", "--disable-component-update",
                 "--disable-sync", "--no-first-run")


def chromium_binary() -> str | None:
    """Debian's chromium (``apt-get install chromium``): /usr/bin/chromium, else the first on PATH."""
    if Path("/usr/bin/chromium").is_file():
        return "/usr/bin/chromium"
    return shutil.which("chromium")


def launch(playwright):
    """Headless Chromium through Playwright (``sync_playwright()``'s object)."""
    binary = chromium_binary()
    if binary is None:
        raise FileNotFoundError("no Chromium binary (/usr/bin/chromium or chromium on PATH): apt-get install chromium")
    return playwright.chromium.launch(executable_path=binary, args=list(CHROMIUM_ARGS))


@contextlib.contextmanager
def serving(app, host: str = "127.0.0.1", port: int = 0):
    """``app`` served by uvicorn in a daemon thread on ``port`` (0: a free one); yields its URL.
    The same port may be served again once the block ends (a server restart under an open page)."""
    import uvicorn

    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM, socket.IPPROTO_TCP)  # TCP: asyncio sets TCP_NODELAY
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    sock.bind((host, port))
    sock.listen(128)
    server = uvicorn.Server(uvicorn.Config(app, log_level="warning"))
    thread = threading.Thread(target=server.run, kwargs={"sockets": [sock]}, daemon=True)
    thread.start()
    for _ in range(600):
        if server.started:
            break
        time.sleep(0.05)
    try:
        yield f"http://{host}:{sock.getsockname()[1]}/"
    finally:
        server.should_exit = True
        thread.join(10)
        sock.close()


__all__ = ["CHROMIUM_ARGS", "chromium_binary", "launch", "serving"]
