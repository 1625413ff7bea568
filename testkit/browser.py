"""Headless Chromium driven over the DevTools protocol (for `hri view`'s page tests and benchmark).

A few calls of the protocol are all we need: open a tab, evaluate JavaScript, take a screenshot. The
websocket is aiohttp's client, so nothing beyond the project's own dependencies is used.
"""

from __future__ import annotations

import asyncio
import base64
import itertools
import json
import os
import re
import shutil
import signal
import subprocess
import tempfile
import time
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from testkit.harness import ProcessGroup

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
FLAGS = [
    "--headless=new",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
    "--hide-scrollbars",
    "--remote-debugging-port=0",
    "--remote-allow-origins=*",
]
# WebGL on the CPU (SwiftShader through ANGLE), for pages that need it (Rerun's web viewer); --disable-gpu goes
WEBGL_FLAGS = ["--use-gl=angle", "--use-angle=swiftshader", "--enable-unsafe-swiftshader"]


def require_chromium():
    import pytest

    if CHROMIUM is None:
        pytest.skip("chromium is not installed (scripts/setup.sh --test installs Debian's chromium)")


class Browser:
    """One headless Chromium process; `tab(url)` opens a page in it."""

    def __init__(self, window: tuple[int, int] = (1400, 900), timeout: float = 60.0, webgl: bool = False):
        if CHROMIUM is None:
            raise RuntimeError("chromium is not installed")
        flags = [f for f in FLAGS if f != "--disable-gpu"] + WEBGL_FLAGS if webgl else FLAGS
        self.profile = tempfile.TemporaryDirectory(prefix="hri-chromium-", ignore_cleanup_errors=True)
        self.proc = subprocess.Popen(
            [
                CHROMIUM,
                *flags,
                f"--user-data-dir={self.profile.name}",
                f"--window-size={window[0]},{window[1]}",
                "about:blank",
            ],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
            start_new_session=True,
        )
        self.loop = asyncio.new_event_loop()
        self.port = self._devtools_port(timeout)
        self.tabs: list[Tab] = []

    def _devtools_port(self, timeout: float) -> int:
        deadline = time.monotonic() + timeout
        assert self.proc.stderr is not None
        while time.monotonic() < deadline:
            line = self.proc.stderr.readline()
            if not line and self.proc.poll() is not None:
                break
            m = re.search(r"DevTools listening on ws://[^:]+:(\d+)/", line)
            if m:
                return int(m.group(1))
        self.close()
        raise RuntimeError("chromium did not start its DevTools endpoint")

    def run(self, coro: Any) -> Any:
        return self.loop.run_until_complete(coro)

    def tab(self, url: str) -> "Tab":
        import aiohttp

        async def open_tab() -> Tab:
            async with aiohttp.ClientSession() as http:
                async with http.put(f"http://127.0.0.1:{self.port}/json/new?{url}") as res:
                    info = await res.json(content_type=None)
            client = aiohttp.ClientSession()
            ws = await client.ws_connect(info["webSocketDebuggerUrl"], max_msg_size=0)
            return Tab(self, client, ws, info["id"])

        tab = self.run(open_tab())
        self.tabs.append(tab)
        return tab

    def close(self) -> None:
        for tab in self.tabs:
            try:
                tab.close()
            except Exception:
                pass
        self.tabs.clear()
        # chromium's renderer and zygote processes are in its session: stop them all, then remove the profile
        for sig in (signal.SIGTERM, signal.SIGKILL):
            try:
                os.killpg(self.proc.pid, sig)
            except ProcessLookupError:
                break
            try:
                self.proc.wait(10)
                time.sleep(0.2)
            except subprocess.TimeoutExpired:
                continue
        if not self.loop.is_closed():
            self.loop.close()
        self.profile.cleanup()


class Tab:
    def __init__(self, browser: Browser, client: Any, ws: Any, target_id: str):
        self.browser, self.client, self.ws, self.id = browser, client, ws, target_id
        self._ids = itertools.count(1)

    def call(self, method: str, **params: Any) -> dict[str, Any]:
        async def go() -> dict[str, Any]:
            n = next(self._ids)
            await self.ws.send_str(json.dumps({"id": n, "method": method, "params": params}))
            while True:
                msg = json.loads((await self.ws.receive(timeout=60)).data)
                if msg.get("id") == n:
                    if "error" in msg:
                        raise RuntimeError(f"{method}: {msg['error']}")
                    return msg["result"]

        return self.browser.run(go())

    def js(self, expression: str) -> Any:
        """The value of a JavaScript expression (awaited if it is a promise)."""
        res = self.call("Runtime.evaluate", expression=expression, returnByValue=True, awaitPromise=True)
        if "exceptionDetails" in res:
            raise RuntimeError(f"JS error in {expression!r}: {res['exceptionDetails']}")
        return res["result"].get("value")

    def wait_for(self, expression: str, timeout: float = 30.0, what: str = "") -> Any:
        deadline = time.monotonic() + timeout
        while True:
            try:
                value = self.js(expression)
            except RuntimeError as exc:
                if "is not defined" not in str(exc) and "of null" not in str(exc):
                    raise
                value = None  # the page has not loaded its script (or that element) yet
            if value:
                return value
            if time.monotonic() > deadline:
                raise TimeoutError(f"page never showed {what or expression} within {timeout} s")
            time.sleep(0.2)

    def screenshot(self, clip: dict[str, float] | None = None) -> bytes:
        params: dict[str, Any] = {"format": "png"}
        if clip:
            params["clip"] = {**clip, "scale": 1}
        return base64.b64decode(self.call("Page.captureScreenshot", **params)["data"])

    def close(self) -> None:
        async def go() -> None:
            await self.ws.close()
            await self.client.close()

        self.browser.run(go())


def start_view(group: ProcessGroup, *args: str, name: str = "view"):
    """Start `hri view --port 0 ARGS` in `group`; (its Proc, the URL it printed)."""
    proc = group.start(name, "hri.cli", "view", "--port", "0", *args)
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        m = re.search(r"hri view: (http://\S+/)", proc.output())
        if m:
            return proc, m.group(1)
        assert proc.alive(), proc.output()
        time.sleep(0.1)
    raise TimeoutError(f"hri view printed no URL:\n{proc.output()}")
