"""Open a Rerun recording, or a warpsim USD file converted to one, in Rerun's viewer: the native
one, or the web viewer served on this machine's loopback address.

Usage analytics stay off. Rerun's viewer sends anonymous usage events unless its analytics are
disabled, which Rerun documents as the command ``rerun analytics disable`` (it writes
``analytics_enabled: false`` to its ``analytics.json``). Every viewer process warpsim starts
runs, on Linux, with ``XDG_CONFIG_HOME`` and ``XDG_DATA_HOME`` pointing into a fresh temporary
folder in which ``rerun analytics disable`` has been run first (checked before the viewer
starts), so the user's own Rerun settings are neither read nor changed; elsewhere (where Rerun
does not follow those variables) warpsim runs ``rerun analytics disable`` for the user, which
Rerun keeps. The viewer also asks GitHub for Rerun's latest release at start (and Rerun's site
for its examples), with no switch to turn that off: warpsim starts it with ``HTTP_PROXY``,
``HTTPS_PROXY`` and ``ALL_PROXY`` naming a port of ``127.0.0.1`` it holds closed (bound, never
listening), and ``NO_PROXY`` for the loopback addresses, so such requests are refused on the
machine before any name is even looked up. Rerun's web viewer page, in the browser, posts the
same events from the page itself (and asks the internet for Rerun's latest release and its
examples) whatever that setting: warpsim therefore never hands the browser Rerun's server
directly. It serves the page through its own small HTTP server on ``127.0.0.1``
(:class:`WebViewer`), which adds a Content-Security-Policy that lets the page connect to this
machine's loopback address only, answers the page's requests to any other address in the page
itself with an empty response (a ``fetch`` wrapper run before Rerun's code), and drops the
page's web-font links. Rerun's servers listen on ``127.0.0.1`` only.

rerun-sdk (which ships the ``rerun`` executable) is the optional ``viewer`` extra.
"""

from __future__ import annotations

import contextlib
import http.server
import importlib.util
import json
import os
import re
import shutil
import socket
import subprocess
import sys
import tempfile
import threading
import time
import urllib.error
import urllib.request
from pathlib import Path
from urllib.parse import quote

from .rerun import SUFFIX, require_rerun, usd_to_rerun

LOOPBACK = "127.0.0.1"
VIEWABLE = (SUFFIX, ".usdc", ".usda")
START_TIMEOUT_S = 60.0  # the web viewer's ports open within a second or two here
COMMAND_TIMEOUT_S = 60.0  # ``rerun analytics ...``: a fraction of a second
POLL_S = 0.1
PROXY_VARIABLES = ("HTTP_PROXY", "HTTPS_PROXY", "ALL_PROXY")
NO_PROXY = "127.0.0.1,localhost,::1"
UPSTREAM_TIMEOUT_S = 60.0  # one file of the viewer's page from Rerun's server (the wasm: 1 s)
FONT_LINKS = re.compile(rb"<link[^>]*fonts\.(?:googleapis|gstatic)\.com[^>]*>", re.S)
HEAD = re.compile(rb"<head[^>]*>", re.I)
#: Run in the page before Rerun's code: requests to other hosts than loopback are answered
#: with an empty 404 without leaving the page (Rerun's analytics, its update check and its
#: examples list: each copes with a failed answer).
FETCH_GUARD = b"""<script>(function () {
  var local = function (u) {
    try { var h = new URL(u, location.href).hostname; }
    catch (e) { return false; }
    return h === "127.0.0.1" || h === "localhost" || h === "[::1]";
  };
  var fetch = window.fetch.bind(window);
  window.fetch = function (input, init) {
    var u = typeof input === "string" ? input : (input && input.url) || String(input);
    return local(u) ? fetch(input, init) : Promise.resolve(new Response("", {status: 404}));
  };
  if (navigator.sendBeacon) {
    var beacon = navigator.sendBeacon.bind(navigator);
    navigator.sendBeacon = function (u, d) { return local(u) ? beacon(u, d) : true; };
  }
})();</script>"""


def rerun_executable() -> str:
    """Path of the ``rerun`` executable that rerun-sdk ships (else one on ``PATH``).

    Raises:
        ModuleNotFoundError: none found; the message names the ``viewer`` extra.
    """
    spec = importlib.util.find_spec("rerun_cli")
    if spec is not None and spec.origin:
        bundled = Path(spec.origin).parent / ("rerun.exe" if os.name == "nt" else "rerun")
        if bundled.is_file():
            return str(bundled)
    found = shutil.which("rerun")
    if found:
        return found
    raise ModuleNotFoundError('the Rerun viewer is needed: pip install "warpsim[viewer]"')


def _analytics_config(env: dict) -> dict:
    """What ``rerun analytics config`` prints in ``env``: Rerun's analytics settings."""
    result = subprocess.run([rerun_executable(), "analytics", "config"], env=env,
                            capture_output=True, text=True, timeout=COMMAND_TIMEOUT_S,
                            check=True)
    text = result.stdout
    return json.loads(text[text.index("{"):text.rindex("}") + 1])


@contextlib.contextmanager
def viewer_environment():
    """The environment for Rerun processes, with usage analytics disabled and every request to
    another host than loopback refused on the machine (module docstring), and a private
    temporary folder (deleted on exit) for what they write.

    Yields:
        ``(env, folder)``: a copy of ``os.environ`` to start processes with, and the folder.

    Raises:
        ModuleNotFoundError: no Rerun executable. RuntimeError: the analytics could not be
            turned off (then nothing is started).
    """
    exe = rerun_executable()
    with tempfile.TemporaryDirectory(prefix="warpsim-rerun-") as folder, \
            socket.socket(socket.AF_INET, socket.SOCK_STREAM) as closed:
        closed.bind((LOOPBACK, 0))  # bound, never listening: connections to it are refused
        proxy = f"http://{LOOPBACK}:{closed.getsockname()[1]}"
        env = dict(os.environ)
        for name in PROXY_VARIABLES:
            env[name] = env[name.lower()] = proxy
        env["NO_PROXY"] = env["no_proxy"] = NO_PROXY
        if sys.platform.startswith("linux"):
            env["XDG_CONFIG_HOME"] = str(Path(folder) / "config")
            env["XDG_DATA_HOME"] = str(Path(folder) / "data")
        subprocess.run([exe, "analytics", "disable"], env=env, capture_output=True,
                       timeout=COMMAND_TIMEOUT_S, check=True)
        config = _analytics_config(env)
        if config.get("analytics_enabled") is not False:
            raise RuntimeError("Rerun's usage analytics could not be turned off "
                               f"({config.get('config_file_path', 'analytics.json')})")
        yield env, Path(folder)


def _free_port(avoid=()) -> int:
    """A port free on the loopback address now (and not in ``avoid``)."""
    while True:
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
            s.bind((LOOPBACK, 0))
            port = int(s.getsockname()[1])
        if port not in avoid:
            return port


def _listening(port: int) -> bool:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.settimeout(POLL_S)
        return s.connect_ex((LOOPBACK, port)) == 0


def content_policy(grpc_port: int) -> str:
    """The Content-Security-Policy of the web viewer's page: scripts, styles, images and
    WebAssembly from the page's own server, connections to it and to Rerun's gRPC server on
    ``127.0.0.1:grpc_port`` only."""
    grpc = f"{LOOPBACK}:{grpc_port}"
    return ("default-src 'self'; "
            "script-src 'self' 'unsafe-inline' 'unsafe-eval' 'wasm-unsafe-eval'; "
            "style-src 'self' 'unsafe-inline'; img-src 'self' data: blob:; "
            "font-src 'self' data:; worker-src 'self' blob:; "
            f"connect-src 'self' http://{grpc} ws://{grpc} http://localhost:{grpc_port}")


def guarded_page(html: bytes) -> bytes:
    """Rerun's viewer page with its web-font links dropped and :data:`FETCH_GUARD` first in
    its ``<head>``."""
    html = FONT_LINKS.sub(b"", html)
    match = HEAD.search(html)
    at = match.end() if match else 0
    return html[:at] + FETCH_GUARD + html[at:]


def _front_handler(upstream: int, policy: str):
    opener = urllib.request.build_opener(urllib.request.ProxyHandler({}))  # never a proxy

    class Front(http.server.BaseHTTPRequestHandler):
        """GET/HEAD from Rerun's page server on ``127.0.0.1:upstream``, with the policy."""

        def _answer(self, send_body: bool) -> None:
            try:
                with opener.open(f"http://{LOOPBACK}:{upstream}{self.path}",
                                 timeout=UPSTREAM_TIMEOUT_S) as response:
                    status, headers, body = response.status, response.headers, response.read()
            except urllib.error.HTTPError as exc:
                status, headers, body = exc.code, exc.headers, exc.read()
            except OSError:
                status, headers, body = 502, {}, b""
            kind = headers.get("Content-Type", "application/octet-stream")
            if kind.startswith("text/html"):
                body = guarded_page(body)
            self.send_response(status)
            self.send_header("Content-Type", kind)
            self.send_header("Content-Length", str(len(body)))
            self.send_header("Content-Security-Policy", policy)
            self.send_header("Cache-Control", "no-store")
            self.end_headers()
            if send_body:
                self.wfile.write(body)

        def do_GET(self):  # noqa: N802 (the http.server protocol)
            self._answer(True)

        def do_HEAD(self):  # noqa: N802
            self._answer(False)

        def log_message(self, *args):  # quiet: the address is printed once
            pass

    return Front


class WebViewer:
    """Rerun's web viewer serving one recording on the loopback address, as a context manager.

    Starts ``rerun RECORDING --serve-web --bind 127.0.0.1`` (an HTTP server for the viewer's
    page and a gRPC server streaming the recording) and, in front of its page server, warpsim's
    own HTTP server on ``127.0.0.1:port`` that adds the page's guards (module docstring); waits
    until all listen.

    Args:
        recording: the ``.rrd`` file.
        env: the environment of the process (from :func:`viewer_environment`).
        port: HTTP port of the page; 0 picks a free one.
        log: file receiving Rerun's output (None: discarded).
        timeout: seconds to wait for the servers [s].

    Attributes:
        url: the address to open in a browser.
        port, grpc_port: the page's and the recording's ports.

    Raises:
        RuntimeError: Rerun's server exited or did not listen within ``timeout`` (the message
            ends with its last output line). OSError: ``port`` is taken.
    """

    def __init__(self, recording, *, env: dict, port: int = 0, log=None,
                 timeout: float = START_TIMEOUT_S):
        self.process = None
        self._front = http.server.ThreadingHTTPServer((LOOPBACK, int(port)), None)
        self.port = int(self._front.server_address[1])
        taken = {self.port}
        upstream = _free_port(taken)
        self.grpc_port = _free_port(taken | {upstream})
        self._front.RequestHandlerClass = _front_handler(upstream, content_policy(self.grpc_port))
        self._thread = threading.Thread(target=self._front.serve_forever, daemon=True)
        self._thread.start()
        proxy = f"rerun+http://{LOOPBACK}:{self.grpc_port}/proxy"
        self.url = f"http://{LOOPBACK}:{self.port}/?url={quote(proxy, safe='')}"
        self._log = Path(log) if log is not None else None
        out = open(self._log, "wb") if self._log is not None else subprocess.DEVNULL  # noqa: SIM115
        try:
            self.process = subprocess.Popen(
                [rerun_executable(), str(recording), "--serve-web", "--bind", LOOPBACK,
                 "--web-viewer-port", str(upstream), "--port", str(self.grpc_port)],
                env=env, stdin=subprocess.DEVNULL, stdout=out, stderr=subprocess.STDOUT)
        except BaseException:
            self.close()
            raise
        finally:
            if out is not subprocess.DEVNULL:
                out.close()
        deadline = time.monotonic() + timeout
        while not (_listening(upstream) and _listening(self.grpc_port)):
            if self.process.poll() is not None or time.monotonic() > deadline:
                self.close()
                raise RuntimeError(f"Rerun's web viewer did not start on {LOOPBACK}"
                                   f"{self._last_line()}")
            time.sleep(POLL_S)

    def _last_line(self) -> str:
        if self._log is None or not self._log.is_file():
            return ""
        lines = self._log.read_text(errors="replace").strip().splitlines()
        return f": {lines[-1].strip()}" if lines else ""

    def wait(self) -> int:
        """Block until Rerun's server exits (Ctrl-C stops it); returns its exit code."""
        return self.process.wait()

    def close(self) -> None:
        """Stop Rerun's server (terminate, then kill after 5 s) and the page server."""
        if self.process is not None and self.process.poll() is None:
            self.process.terminate()
            try:
                self.process.wait(timeout=5.0)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        self._front.shutdown()
        self._front.server_close()

    def __enter__(self) -> WebViewer:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def check_viewable(path) -> Path:
    """``path`` as a :class:`pathlib.Path` once it is an existing ``.rrd``, ``.usdc`` or
    ``.usda`` file.

    Raises:
        ValueError: another extension. FileNotFoundError: no such file.
    """
    path = Path(path)
    if path.suffix.lower() not in VIEWABLE:
        raise ValueError(f"view needs a .rrd recording or a warpsim .usdc/.usda file, "
                         f"got {str(path)!r}")
    if not path.is_file():
        raise FileNotFoundError(f"no file at {str(path)!r}")
    return path


def view(path, *, web: bool = False, port: int = 0, open_browser: bool = True,
         stride: int = 1, sample: int | None = None, echo=print) -> int:
    """Open a recording (or a warpsim USD file, converted first) in Rerun's viewer and wait
    until it is closed (native) or stopped with Ctrl-C (web).

    Args:
        path: a ``.rrd``, or a ``.usdc``/``.usda`` written by warpsim (single or sharded root).
        web: serve the web viewer on ``127.0.0.1`` instead of starting the native one.
        port: with ``web``, the HTTP port (0: a free one).
        open_browser: with ``web``, open the address in the default browser.
        stride, sample: for USD files, as :func:`warpsim.export.rerun.write_rerun`'s.
        echo: where the web viewer's address is announced.

    Returns:
        The viewer's exit code.

    Raises:
        ValueError, FileNotFoundError: a bad path. ModuleNotFoundError: rerun-sdk missing.
        RuntimeError: the viewer could not be started with its analytics off.
    """
    path = check_viewable(path)
    require_rerun()
    with viewer_environment() as (env, folder):
        recording = path
        if path.suffix.lower() != SUFFIX:
            recording = usd_to_rerun(path, folder / f"{path.stem}.rrd", stride=stride,
                                     sample=sample)
        if not web:
            # --new: a viewer of its own (not one already listening, started otherwise)
            return subprocess.run([rerun_executable(), str(recording), "--bind", LOOPBACK,
                                   "--new"], env=env, stdin=subprocess.DEVNULL).returncode
        with WebViewer(recording, env=env, port=port, log=folder / "viewer.log") as viewer:
            echo(f"Rerun web viewer for {path}: {viewer.url} (Ctrl-C stops it)")
            if open_browser:
                import webbrowser

                webbrowser.open(viewer.url)
            return viewer.wait()


__all__ = ["WebViewer", "check_viewable", "rerun_executable", "view", "viewer_environment"]
