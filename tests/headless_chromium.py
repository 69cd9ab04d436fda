"""A headless Chromium driven over the DevTools protocol on a pipe (``--remote-debugging-pipe``:
NUL-terminated JSON messages on file descriptors 3 and 4), with no network but loopback.

Every request the page makes goes through the protocol's ``Fetch`` domain: loopback requests
continue, any other is answered here with an empty 200 response and never leaves the machine
(and ``--host-resolver-rules`` maps every other host name to nothing, a second guard). The
client records every URL requested, console message and exception.
"""

from __future__ import annotations

import base64
import fcntl
import json
import os
import select
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from urllib.parse import urlsplit

#: Started with the two pipe ends and Chromium's command line: puts the ends on descriptors 3
#: and 4, where ``--remote-debugging-pipe`` expects them, then becomes Chromium.
TRAMPOLINE = ("import os, sys; os.dup2(int(sys.argv[1]), 3); os.dup2(int(sys.argv[2]), 4); "
              "os.execv(sys.argv[3], sys.argv[3:])")
LOOPBACK_HOSTS = ("127.0.0.1", "localhost", "[::1]", "::1")
FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--disable-default-apps", "--disable-extensions", "--mute-audio",
         "--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--remote-debugging-pipe",
         "--host-resolver-rules=MAP * ~NOTFOUND, EXCLUDE 127.0.0.1, EXCLUDE localhost"]


def chromium_path() -> str | None:
    """The Chromium executable of the system's package, or None."""
    for name in ("chromium", "chromium-browser", "google-chrome"):
        found = shutil.which(name)
        if found:
            return found
    return None


def _above_4(fd: int) -> int:
    """The same pipe end under a descriptor number >= 10 (``fd`` is closed)."""
    high = fcntl.fcntl(fd, fcntl.F_DUPFD, 10)
    os.close(fd)
    return high


def is_loopback(url: str) -> bool:
    parts = urlsplit(url)
    if parts.scheme in ("data", "blob", "about", "chrome", "devtools"):
        return True
    return (parts.hostname or "") in LOOPBACK_HOSTS


class Browser:
    """One headless Chromium with one page; use as a context manager (killed on exit)."""

    def __init__(self, executable: str, size=(1280, 800)):
        self._folder = tempfile.TemporaryDirectory(prefix="warpsim-chromium-",
                                                   ignore_cleanup_errors=True)
        to_child_r, self._to_child = os.pipe()
        self._from_child, from_child_w = os.pipe()
        # the child's ends above 4, so that moving them to 3 and 4 never overwrites one
        to_child_r, from_child_w = _above_4(to_child_r), _above_4(from_child_w)
        args = [executable, *FLAGS, f"--user-data-dir={self._folder.name}",
                f"--window-size={size[0]},{size[1]}", "about:blank"]
        self.log = Path(self._folder.name) / "chromium.log"
        with open(self.log, "wb") as log:
            self.process = subprocess.Popen([sys.executable, "-c", TRAMPOLINE, str(to_child_r),
                                             str(from_child_w), *args],
                                            pass_fds=(to_child_r, from_child_w),
                                            stdin=subprocess.DEVNULL, stdout=log, stderr=log,
                                            start_new_session=True)
        os.close(to_child_r)
        os.close(from_child_w)
        self._buffer = b""
        self._next_id = 0
        self.events: list[dict] = []
        self.requested: list[str] = []
        self.blocked: list[str] = []
        self.console: list[tuple[str, str]] = []  # (level, text)
        self.exceptions: list[str] = []
        self.session = None

    def last_words(self) -> str:
        """``": "`` and the last line Chromium printed, or ``""``."""
        try:
            lines = self.log.read_text(errors="replace").strip().splitlines()
        except OSError:
            return ""
        return f": {lines[-1].strip()}" if lines else ""

    # -- protocol -------------------------------------------------------------------------

    def _send(self, method: str, params: dict | None = None, session: str | None = None) -> int:
        self._next_id += 1
        message = {"id": self._next_id, "method": method, "params": params or {}}
        if session:
            message["sessionId"] = session
        try:
            os.write(self._to_child, json.dumps(message).encode() + b"\0")
        except BrokenPipeError:
            raise RuntimeError(f"Chromium exited{self.last_words()}") from None
        return self._next_id

    def _read(self, timeout: float) -> dict | None:
        while b"\0" not in self._buffer:
            ready, _, _ = select.select([self._from_child], [], [], timeout)
            if not ready:
                return None
            chunk = os.read(self._from_child, 1 << 20)
            if not chunk:
                raise RuntimeError(f"Chromium closed its DevTools pipe{self.last_words()}")
            self._buffer += chunk
        raw, self._buffer = self._buffer.split(b"\0", 1)
        return json.loads(raw)

    def _handle(self, message: dict) -> None:
        method, params = message.get("method"), message.get("params", {})
        if method == "Fetch.requestPaused":
            url = params["request"]["url"]
            self.requested.append(url)
            if is_loopback(url):
                self._send("Fetch.continueRequest", {"requestId": params["requestId"]},
                           self.session)
            else:
                self.blocked.append(url)
                self._send("Fetch.fulfillRequest", {"requestId": params["requestId"],
                                                    "responseCode": 200, "body": ""},
                           self.session)
        elif method == "Runtime.consoleAPICalled":
            text = " ".join(str(a.get("value", a.get("description", "")))
                            for a in params.get("args", []))
            self.console.append((params.get("type", ""), text))
        elif method == "Log.entryAdded":
            entry = params.get("entry", {})
            self.console.append((entry.get("level", ""), entry.get("text", "")))
        elif method == "Runtime.exceptionThrown":
            details = params.get("exceptionDetails", {})
            self.exceptions.append(details.get("exception", {}).get("description")
                                   or details.get("text", ""))
        self.events.append(message)

    def call(self, method: str, params: dict | None = None, *, timeout: float = 30.0,
             session: str | None = "page") -> dict:
        """Send a command (to the page's session unless ``session=None``) and return its
        result, handling the events that arrive meanwhile."""
        sid = self.session if session == "page" else session
        wanted = self._send(method, params, sid)
        deadline = time.monotonic() + timeout
        while True:
            left = deadline - time.monotonic()
            message = self._read(max(left, 0.0)) if left > 0 else None
            if message is None:
                raise TimeoutError(f"no answer to {method} within {timeout} s")
            if message.get("id") == wanted:
                if "error" in message:
                    raise RuntimeError(f"{method}: {message['error']}")
                return message.get("result", {})
            self._handle(message)

    def pump(self, seconds: float) -> None:
        """Handle events for ``seconds``."""
        deadline = time.monotonic() + seconds
        while (left := deadline - time.monotonic()) > 0:
            message = self._read(left)
            if message is not None:
                self._handle(message)

    # -- page -----------------------------------------------------------------------------

    def open(self, url: str) -> None:
        """Attach to the page, intercept its requests, and navigate to ``url``."""
        targets = self.call("Target.getTargets", session=None)["targetInfos"]
        page = next(t for t in targets if t["type"] == "page")
        self.session = self.call("Target.attachToTarget",
                                 {"targetId": page["targetId"], "flatten": True},
                                 session=None)["sessionId"]
        self.call("Fetch.enable", {"patterns": [{"urlPattern": "*"}]})
        for domain in ("Runtime", "Log", "Page"):
            self.call(f"{domain}.enable")
        self.call("Page.navigate", {"url": url})

    def evaluate(self, expression: str):
        result = self.call("Runtime.evaluate", {"expression": expression,
                                                "returnByValue": True})
        return result.get("result", {}).get("value")

    def screenshot(self, path, timeout: float = 120.0) -> Path:
        """A PNG of the page; a software-rendered page on a busy machine may take a minute."""
        data = self.call("Page.captureScreenshot", {"format": "png"}, timeout=timeout)["data"]
        path = Path(path)
        path.write_bytes(base64.b64decode(data))
        return path

    def close(self) -> None:
        """Kill Chromium and every process it started (its own session: the renderers and
        helpers outlive a kill of the browser alone and go on writing into the profile), wait
        for them to go, then remove the profile."""
        group = self.process.pid
        try:
            os.killpg(group, signal.SIGKILL)
        except ProcessLookupError:
            pass
        self.process.wait()
        deadline = time.monotonic() + 10.0
        while time.monotonic() < deadline:
            try:
                os.killpg(group, 0)
            except ProcessLookupError:
                break
            time.sleep(0.05)
        for fd in (self._to_child, self._from_child):
            try:
                os.close(fd)
            except OSError:
                pass
        self._folder.cleanup()

    def __enter__(self) -> Browser:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
