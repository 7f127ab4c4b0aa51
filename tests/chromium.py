"""Debian's Chromium, headless, driven over the DevTools protocol: open a page, take screenshots.

The protocol runs over a pair of pipes (`--remote-debugging-pipe`: Chromium reads commands on
its fd 3 and writes replies on its fd 4, each a JSON message ending in a NUL byte), so no
websocket client is needed. WebGL is software-rendered (SwiftShader), as on a machine
without a GPU.
"""

from __future__ import annotations

import base64
import contextlib
import io
import json
import os
import select
import shutil
import subprocess
import tempfile
import time
from pathlib import Path
from typing import Any

CHROMIUM_PATHS = ("/usr/bin/chromium", "/usr/bin/chromium-browser")
REPLY_TIMEOUT_S = 120.0  # a screenshot of a busy page on a loaded machine takes seconds


def find_chromium() -> str | None:
    """The Chromium binary, or None where none is installed."""
    for path in CHROMIUM_PATHS:
        if os.access(path, os.X_OK):
            return path
    return shutil.which("chromium")


class Chromium:
    """One headless Chromium with one page; `close()` ends it (and its children)."""

    def __init__(self, binary: str, width: int = 1600, height: int = 1000) -> None:
        self._profile = tempfile.TemporaryDirectory(prefix="groundfx-chromium-")
        to_chrome_r, self._to_chrome = os.pipe()
        self._from_chrome, from_chrome_w = os.pipe()

        def plumb() -> None:  # in the child: the protocol's pipes on fds 3 and 4
            os.dup2(to_chrome_r, 3)
            os.dup2(from_chrome_w, 4)

        args = [
            binary,
            "--headless=new",
            "--remote-debugging-pipe",
            f"--user-data-dir={self._profile.name}",
            f"--window-size={width},{height}",
            "--no-sandbox",  # CI runs as root
            "--no-first-run",
            "--no-default-browser-check",
            "--disable-extensions",
            "--use-angle=swiftshader",
            "--enable-unsafe-swiftshader",
            "--hide-scrollbars",
            "--mute-audio",
            "--disable-breakpad",  # no crash handler, which would outlive the browser
            "--disable-crash-reporter",
        ]
        self.process = subprocess.Popen(
            args,
            preexec_fn=plumb,
            pass_fds=(3, 4),  # kept open after `plumb` put the pipes there
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            start_new_session=True,  # its renderer and GPU processes end with its group
        )
        os.close(to_chrome_r)
        os.close(from_chrome_w)
        self._buffer = b""
        self._next_id = 0
        self._session: str | None = None
        self._width, self._height = width, height

    def call(self, method: str, params: dict[str, Any] | None = None) -> dict[str, Any]:
        """One protocol command on the page (once opened); its result."""
        self._next_id += 1
        message: dict[str, Any] = {"id": self._next_id, "method": method, "params": params or {}}
        if self._session is not None and not method.startswith("Target."):
            message["sessionId"] = self._session
        os.write(self._to_chrome, json.dumps(message).encode() + b"\0")
        while True:
            reply = self._read()
            if reply.get("id") == self._next_id:
                if "error" in reply:
                    raise RuntimeError(f"{method}: {reply['error']}")
                return reply.get("result", {})

    def _read(self) -> dict[str, Any]:
        deadline = time.monotonic() + REPLY_TIMEOUT_S
        while b"\0" not in self._buffer:
            left = deadline - time.monotonic()
            if left <= 0 or not select.select([self._from_chrome], [], [], left)[0]:
                raise RuntimeError(f"Chromium did not reply within {REPLY_TIMEOUT_S:g} s")
            data = os.read(self._from_chrome, 1 << 20)
            if not data:
                raise RuntimeError("Chromium closed its DevTools pipe")
            self._buffer += data
        message, self._buffer = self._buffer.split(b"\0", 1)
        return json.loads(message)

    def open(self, url: str) -> None:
        # the page opens at `url`: a navigation from another page could move it to another
        # renderer process, and detach the session from it
        target = self.call("Target.createTarget", {"url": url})["targetId"]
        self._session = self.call("Target.attachToTarget", {"targetId": target, "flatten": True})[
            "sessionId"
        ]
        self.call(
            "Emulation.setDeviceMetricsOverride",
            {"width": self._width, "height": self._height, "deviceScaleFactor": 1, "mobile": False},
        )

    def screenshot(self, fmt: str = "png", box: tuple[int, int, int, int] | None = None) -> Any:
        """The page, or its part `box` (left, top, right, bottom), as a PIL image (RGB);
        `fmt` "jpeg" is faster to take, "png" exact (JPEG blurs thin coloured lines)."""
        from PIL import Image

        params: dict[str, Any] = {"format": fmt}
        if box is not None:
            left, top, right, bottom = box
            params["clip"] = {
                "x": left, "y": top, "width": right - left, "height": bottom - top, "scale": 1
            }  # fmt: skip
        if fmt == "jpeg":
            params["quality"] = 70
        data = self.call("Page.captureScreenshot", params)["data"]
        return Image.open(io.BytesIO(base64.b64decode(data))).convert("RGB")

    def save_screenshot(self, path: Path) -> Any:
        image = self.screenshot()
        image.save(path)
        return image

    def close(self) -> None:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(self.process.pid, 15)
        try:
            self.process.wait(timeout=10)
        except subprocess.TimeoutExpired:
            os.killpg(self.process.pid, 9)
            self.process.wait()
        for fd in (self._to_chrome, self._from_chrome):
            with contextlib.suppress(OSError):
                os.close(fd)
        self._profile.cleanup()

    def __enter__(self) -> Chromium:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
