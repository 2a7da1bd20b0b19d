"""A headless Chromium (Debian's package) driven over the Chrome DevTools Protocol, for the page tests.

The browser is started by PID with a fresh profile and stopped by PID; its DevTools
endpoint is read from the line it prints ("DevTools listening on ws://..."). Commands go
over a WebSocket (the same ``websockets`` client the server's tests use).
"""

from __future__ import annotations

import itertools
import json
import queue
import re
import shutil
import subprocess
import tempfile
import threading
import time
import urllib.request
from typing import Any

from websockets.sync.client import ClientConnection, connect

from conftest import require_program

#: Longest wait for the browser to start, or for one command's answer (s).
TIMEOUT_S = 60.0
#: The flags the issue names for Debian's headless Chromium, and a fixed window.
FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--remote-debugging-port=0", "--window-size=1280,1000")
_LISTENING = re.compile(r"DevTools listening on (ws://\S+)")


class Browser:
    """Chromium showing ``url`` (loaded when made) until :meth:`close`; :meth:`call` sends a command to that
    page, :meth:`evaluate` runs JavaScript in it."""

    def __init__(self, url: str):
        binary = require_program("chromium")
        self.profile = tempfile.mkdtemp(prefix="tpad-rt-chromium-")
        self.process = subprocess.Popen([binary, *FLAGS, f"--user-data-dir={self.profile}", "about:blank"],
                                        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        self.log: list[str] = []
        browser_url = self._wait_listening()
        port = re.search(r":(\d+)/", browser_url).group(1)  # type: ignore[union-attr]
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list", timeout=TIMEOUT_S) as answer:
            pages = [target for target in json.load(answer) if target["type"] == "page"]
        assert pages, "Chromium opened no page"
        self.page: ClientConnection = connect(pages[0]["webSocketDebuggerUrl"], max_size=None,
                                              open_timeout=TIMEOUT_S).__enter__()
        self._ids = itertools.count(1)
        self.events: list[dict[str, Any]] = []
        self.call("Page.enable")
        self.call("Page.navigate", url=url)
        self.wait_event("Page.loadEventFired")

    def _wait_listening(self) -> str:
        lines: queue.Queue[str | None] = queue.Queue()

        def read() -> None:
            assert self.process.stderr is not None
            for line in self.process.stderr:
                lines.put(line)
            lines.put(None)

        threading.Thread(target=read, daemon=True).start()
        deadline = time.monotonic() + TIMEOUT_S
        while True:
            try:
                line = lines.get(timeout=max(deadline - time.monotonic(), 0.0))
            except queue.Empty:
                self.close()
                raise AssertionError(f"Chromium did not open DevTools: {''.join(self.log)[-2000:]}") from None
            if line is None:
                self.close()
                raise AssertionError(f"Chromium ended: {''.join(self.log)[-2000:]}")
            self.log.append(line)
            found = _LISTENING.search(line)
            if found:
                return found.group(1)

    def call(self, method: str, **params: Any) -> dict[str, Any]:
        """Send a DevTools command; its result (AssertionError for a protocol error)."""
        command_id = next(self._ids)
        self.page.send(json.dumps({"id": command_id, "method": method, "params": params}))
        deadline = time.monotonic() + TIMEOUT_S
        while True:
            message = json.loads(self.page.recv(timeout=max(deadline - time.monotonic(), 0.0)))
            if message.get("id") == command_id:
                assert "error" not in message, (method, message["error"])
                return message["result"]
            if "method" in message:
                self.events.append(message)

    def wait_event(self, method: str) -> dict[str, Any]:
        """The first event ``method`` not yet waited for (AssertionError after TIMEOUT_S)."""
        deadline = time.monotonic() + TIMEOUT_S
        while True:
            for index, event in enumerate(self.events):
                if event["method"] == method:
                    return self.events.pop(index)
            left = deadline - time.monotonic()
            assert left > 0, f"no {method} event within {TIMEOUT_S:g} s"
            message = json.loads(self.page.recv(timeout=left))
            if "method" in message:
                self.events.append(message)

    def evaluate(self, expression: str) -> Any:
        """The value of a JavaScript expression in the page (promises awaited); AssertionError if it threw."""
        result = self.call("Runtime.evaluate", expression=expression, awaitPromise=True, returnByValue=True)
        assert "exceptionDetails" not in result, result["exceptionDetails"]
        return result["result"].get("value")

    def close(self) -> None:
        if getattr(self, "page", None) is not None:
            self.page.close()
        if self.process.poll() is None:
            self.process.kill()
        self.process.wait()
        shutil.rmtree(self.profile, ignore_errors=True)

    def __enter__(self) -> Browser:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
