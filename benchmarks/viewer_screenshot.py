"""A screenshot of the browser viewer (``kinlearn.viz.show_plan``) taken with headless Chromium.

    python benchmarks/viewer_screenshot.py [--out docs/figures/viewer.png] [--chromium chromium]
                                           [--frame 6] [--settle 6]

Shows the iiwa14 on the shipped planner's plan of ``make_animation.py`` (its waypoints, the executed
end-effector path, the arm at configuration ``--frame``). The viewer is served on a free localhost
port; Chromium (Debian's ``chromium`` package) runs headless with WebGL in software (SwiftShader) and
is driven over the Chrome DevTools protocol (the ``websockets`` package that viser installs): open
the page, wait until the viewer has connected and drawn its canvas, hide the client's notice that
WebGL runs in software, wait ``--settle`` seconds, capture the page. Nothing leaves the machine.
"""

from __future__ import annotations

import argparse
import base64
import json
import os
import shutil
import socket
import subprocess
import sys
import tempfile
import time
import urllib.request
from pathlib import Path

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from make_animation import demo_plan

from kinlearn.io import atomic_write
from kinlearn.viz import show_plan

ROOT = Path(__file__).resolve().parents[1]
WIDTH, HEIGHT = 1200, 800
CHROMIUM_FLAGS = (
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--hide-scrollbars",
    f"--window-size={WIDTH},{HEIGHT}",
)
HIDE_NOTICES = """
(() => {
  const style = document.createElement('style');
  style.textContent = '.mantine-Notifications-root { display: none !important; }';
  document.head.appendChild(style);
  return true;
})()
"""
READY = """
(() => {
  const drawn = [...document.querySelectorAll('canvas')].some((c) => c.width > 0 && c.height > 0);
  return drawn && document.body.innerText.includes('Connected');
})()
"""


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class DevTools:
    """The few Chrome DevTools protocol calls this script needs, over one page's websocket."""

    def __init__(self, ws_url: str):
        from websockets.sync.client import connect

        self.ws = connect(ws_url, max_size=64 * 1024 * 1024, open_timeout=30)
        self.next_id = 0

    def call(self, method: str, **params):
        self.next_id += 1
        self.ws.send(json.dumps({"id": self.next_id, "method": method, "params": params}))
        while True:
            msg = json.loads(self.ws.recv(timeout=120))
            if msg.get("id") == self.next_id:
                if "error" in msg:
                    raise RuntimeError(f"{method}: {msg['error']}")
                return msg["result"]

    def evaluate(self, expression: str):
        return self.call("Runtime.evaluate", expression=expression, returnByValue=True)["result"].get("value")

    def close(self) -> None:
        self.ws.close()


def _page_websocket(profile: Path, proc: subprocess.Popen, timeout: float = 60.0) -> str:
    """The DevTools websocket of Chromium's first page (Chromium writes its port into the profile)."""
    port_file = profile / "DevToolsActivePort"
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise RuntimeError(f"chromium exited with code {proc.returncode}")
        if port_file.is_file() and port_file.read_text().strip():
            port = int(port_file.read_text().split()[0])
            with urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list", timeout=10) as resp:
                pages = [t for t in json.load(resp) if t.get("type") == "page"]
            if pages:
                return pages[0]["webSocketDebuggerUrl"]
        time.sleep(0.2)
    raise RuntimeError("chromium did not open its DevTools port in time")


def screenshot(url: str, out: Path, chromium: str, settle: float) -> Path:
    profile = Path(tempfile.mkdtemp(prefix="kinlearn-chromium-"))
    proc = subprocess.Popen(
        [chromium, *CHROMIUM_FLAGS, f"--user-data-dir={profile}", "--remote-debugging-port=0", "about:blank"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        dt = DevTools(_page_websocket(profile, proc))
        try:
            dt.call("Page.enable")
            dt.call(
                "Emulation.setDeviceMetricsOverride",
                width=WIDTH,
                height=HEIGHT,
                deviceScaleFactor=1,
                mobile=False,
            )
            dt.call("Page.navigate", url=url)
            deadline = time.monotonic() + 90
            while not dt.evaluate(READY):
                if time.monotonic() > deadline:
                    raise RuntimeError("the viewer page did not connect and draw within 90 s")
                time.sleep(0.5)
            dt.evaluate(HIDE_NOTICES)
            time.sleep(settle)  # let the scene arrive and the software renderer draw it
            png = base64.b64decode(dt.call("Page.captureScreenshot", format="png")["data"])
        finally:
            dt.close()
    finally:
        proc.terminate()
        try:
            proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        shutil.rmtree(profile, ignore_errors=True)
    return atomic_write(out, lambda tmp: tmp.write_bytes(png))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "figures" / "viewer.png")
    ap.add_argument("--chromium", default="chromium", help="the Chromium executable")
    ap.add_argument("--frame", type=int, default=6, help="the plan configuration shown")
    ap.add_argument("--settle", type=float, default=6.0, help="seconds to wait before the capture")
    args = ap.parse_args()
    torch.set_num_threads(1)
    if shutil.which(args.chromium) is None:
        sys.exit(f"{args.chromium} not found: `apt-get install -y chromium` (Debian) or pass --chromium PATH")

    t0 = time.perf_counter()
    robot, plan = demo_plan()
    viewer = show_plan(robot, plan.joints, waypoints=plan.waypoints, port=_free_port(), block=False)
    try:
        viewer.set_frame(args.frame)
        out = screenshot(viewer.url, args.out, args.chromium, args.settle)
    finally:
        viewer.close()
    version = subprocess.run([args.chromium, "--version"], capture_output=True, text=True).stdout.strip()
    print(f"wrote {out} ({out.stat().st_size / 1e3:.0f} kB, {WIDTH}×{HEIGHT}) with {version} "
          f"in {time.perf_counter() - t0:.1f} s")  # fmt: skip


if __name__ == "__main__":
    main()
