"""Headless Chromium driven over its DevTools protocol, for the browser check of the book.

Debian's ``chromium`` package provides the browser (``apt-get install -y chromium``; ``.ci/run``
installs it when missing); :mod:`websocket` (the ``websocket-client`` package) speaks the
protocol. Every request that is not ``file:``, ``data:``, ``blob:`` or ``about:`` is blocked and
recorded, so a page that would fetch from another machine is seen, never served.
"""

from __future__ import annotations

import base64
import json
import os
import shutil
import subprocess
import tempfile
import time
import urllib.request
from dataclasses import dataclass, field
from pathlib import Path

INSTALL_HINT = "apt-get update && apt-get install -y chromium"
LOCAL_SCHEMES = ("file:", "data:", "blob:", "about:", "devtools:")


def find_chromium() -> str | None:
    """Path of the Chromium binary (``$CHROMIUM``, then ``chromium`` on PATH), or None."""
    for name in (os.environ.get("CHROMIUM"), "chromium", "chromium-browser"):
        if name and (path := shutil.which(name)):
            return path
    return None


@dataclass
class PageReport:
    """What one page load showed: console errors, requests that left the machine, and every
    URL requested (``data:`` URLs aside)."""

    url: str
    errors: list[str] = field(default_factory=list)
    remote_requests: list[str] = field(default_factory=list)
    requests: list[str] = field(default_factory=list)


class Chromium:
    """One headless Chromium with one tab, driven synchronously over the DevTools protocol.

    Parameters
    ----------
    binary : str
        The Chromium executable.
    width, height : int
        Window size in CSS pixels (device scale factor 1).
    """

    def __init__(self, binary: str, width: int = 1400, height: int = 900):
        import websocket

        self.width, self.height = width, height
        self._profile = tempfile.mkdtemp(prefix="calstudy-chromium-")
        args = [
            binary,
            "--headless=new",
            "--no-sandbox",  # CI runs as root
            "--disable-gpu",
            "--disable-dev-shm-usage",
            "--no-first-run",
            "--no-default-browser-check",
            "--disable-extensions",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--hide-scrollbars",
            "--remote-debugging-port=0",
            f"--user-data-dir={self._profile}",
            f"--window-size={width},{height}",
            "about:blank",
        ]
        self._proc = subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        try:
            port = self._port()
            with urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list", timeout=10) as r:
                targets = json.load(r)
            page = next(t for t in targets if t["type"] == "page")
            self._ws = websocket.create_connection(
                page["webSocketDebuggerUrl"], timeout=60, suppress_origin=True
            )
        except BaseException:
            self.close()
            raise
        self._id = 0
        self._events: list[dict] = []
        for domain in ("Page", "Runtime", "Log", "Network"):
            self.send(f"{domain}.enable")
        self.send("Network.setBlockedURLs", urls=["http://*", "https://*", "ws://*", "wss://*"])
        self.send("Network.setCacheDisabled", cacheDisabled=True)
        self._metrics(height)

    def _metrics(self, height: int) -> None:
        self.send(
            "Emulation.setDeviceMetricsOverride",
            width=self.width, height=height, deviceScaleFactor=1, mobile=False,
        )

    def _port(self, timeout: float = 30.0) -> int:
        marker = Path(self._profile) / "DevToolsActivePort"
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if self._proc.poll() is not None:
                raise RuntimeError(f"chromium exited with code {self._proc.returncode}")
            if marker.is_file() and (lines := marker.read_text().split()):
                return int(lines[0])
            time.sleep(0.1)
        raise RuntimeError(f"chromium did not open its DevTools port within {timeout:.0f} s")

    def close(self) -> None:
        """End the browser and remove its profile."""
        ws = getattr(self, "_ws", None)
        if ws is not None:
            ws.close()
        if self._proc.poll() is None:
            self._proc.terminate()
            try:
                self._proc.wait(10)
            except subprocess.TimeoutExpired:
                self._proc.kill()
                self._proc.wait()
        shutil.rmtree(self._profile, ignore_errors=True)

    def __enter__(self) -> Chromium:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # -- protocol ------------------------------------------------------------------------------

    def send(self, method: str, **params):
        """Call ``method`` and return its result; events that arrive meanwhile are queued."""
        self._id += 1
        self._ws.send(json.dumps({"id": self._id, "method": method, "params": params}))
        while True:
            msg = json.loads(self._ws.recv())
            if msg.get("id") == self._id:
                if "error" in msg:
                    raise RuntimeError(f"{method}: {msg['error'].get('message')}")
                return msg.get("result", {})
            if "method" in msg:
                self._events.append(msg)

    def _wait_event(self, name: str, timeout: float) -> None:
        end = time.monotonic() + timeout
        while not any(e["method"] == name for e in self._events):
            if time.monotonic() > end:
                raise TimeoutError(f"no {name} within {timeout:.0f} s")
            self._ws.settimeout(max(0.1, end - time.monotonic()))
            msg = json.loads(self._ws.recv())
            if "method" in msg:
                self._events.append(msg)
        self._ws.settimeout(60)

    def evaluate(self, expression: str):
        """Value of a JavaScript expression (awaited if it is a promise)."""
        result = self.send(
            "Runtime.evaluate", expression=expression, awaitPromise=True, returnByValue=True
        )
        if "exceptionDetails" in result:
            d = result["exceptionDetails"]
            raise RuntimeError(f"script failed: {d.get('exception', {}).get('description')}")
        return result["result"].get("value")

    # -- pages ---------------------------------------------------------------------------------

    def open(self, url: str, timeout: float = 60.0) -> PageReport:
        """Load ``url``, wait for it, for MathJax and for its images; report what went wrong."""
        self._events.clear()
        self.send("Page.navigate", url=url)
        self._wait_event("Page.loadEventFired", timeout)
        for _ in range(3):  # a page that redirects (index.html) loads a second time
            try:
                self.evaluate(_SETTLE)
                break
            except RuntimeError as e:
                if "navigated" not in str(e):
                    raise
                self._events = [e for e in self._events if e["method"] != "Page.loadEventFired"]
                self._wait_event("Page.loadEventFired", timeout)
        # drain events that arrived while settling
        self.send("Runtime.evaluate", expression="0")
        report = PageReport(url)
        for e in self._events:
            p = e.get("params", {})
            if e["method"] == "Runtime.consoleAPICalled" and p.get("type") in ("error", "assert"):
                args = " ".join(str(a.get("value", a.get("description", ""))) for a in p["args"])
                report.errors.append(f"console.{p['type']}: {args}")
            elif e["method"] == "Runtime.exceptionThrown":
                d = p["exceptionDetails"]
                text = d.get("exception", {}).get("description") or d.get("text")
                report.errors.append(f"exception: {text}")
            elif e["method"] == "Log.entryAdded" and p["entry"]["level"] == "error":
                entry = p["entry"]
                report.errors.append(f"log: {entry['text']} {entry.get('url', '')}".strip())
            elif e["method"] == "Network.requestWillBeSent":
                req = p["request"]["url"]
                if not req.startswith("data:"):
                    report.requests.append(req)
                if not req.startswith(LOCAL_SCHEMES):
                    report.remote_requests.append(req)
        return report

    def screenshot(self, path: Path, max_height: int = 20000) -> Path:
        """Write a PNG of the whole page at the window width."""
        size = self.send("Page.getLayoutMetrics")["cssContentSize"]
        height = min(int(size["height"]) + 1, max_height)
        # a window as tall as the page, so that fixed sidebars are laid out as a reader sees them
        self._metrics(height)
        try:
            shot = self.send("Page.captureScreenshot", format="png")
        finally:
            self._metrics(self.height)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(base64.b64decode(shot["data"]))
        return path


# After the load event: typeset math (MathJax 3 starts typesetting on load) and decode every
# image, lazy ones included, so that the checks see the page as a reader does.
_SETTLE = """
(async () => {
  const mj = window.MathJax;
  if (mj && mj.startup && mj.startup.promise) { await mj.startup.promise; }
  for (const img of document.images) { img.loading = 'eager'; }
  await Promise.all([...document.images].map(i => i.decode().catch(() => null)));
  return true;
})()
"""
