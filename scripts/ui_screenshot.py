"""A screenshot of a page of the Dagster UI with headless Chromium, for the docs and for checking the UI by eye.

Drives Chromium over its DevTools protocol: opens the page, dismisses the UI's first-visit dialog (its "Skip"
button), waits for the page to settle and writes a PNG. Needs ``chromium`` on PATH (Debian: ``apt-get install
chromium``) and a running UI (``humancal ui``).

    humancal ui --port 3777 &
    python scripts/ui_screenshot.py "http://127.0.0.1:3777/assets/fitted_motions?view=lineage&lineageScope=upstream" \
        /tmp/lineage.png [--size 1600x1000] [--wait 8] [--expect-images N]
    python scripts/ui_screenshot.py "http://127.0.0.1:3777/assets/fitted_motions?partition=synthetic__demo" \
        /tmp/errors.png --show-markdown errors_per_view --expect-images 1

``--show-markdown KEY`` opens the Markdown of the metadata entry KEY (the UI shows a picture there behind a "Show
Markdown" link) before the shot.

It prints how many pictures the page shows (``<img>`` elements holding an inline PNG, as the asset pages' metadata
pictures are, that the browser decoded); ``--expect-images N`` exits with status 1 when there are fewer than N.
"""

from __future__ import annotations

import argparse
import asyncio
import base64
import json
import shutil
import subprocess
import tempfile
import time
import urllib.request
from pathlib import Path

import websockets

_DISMISS = """[...document.querySelectorAll('button')].filter(b => b.textContent.trim() === 'Skip')
              .forEach(b => b.click()).length"""
_SHOW_MARKDOWN = """(() => {{
  const row = [...document.querySelectorAll('tr')].find(r => r.cells.length && r.cells[0].textContent.trim() === {key});
  if (!row) return 'no metadata row ' + {key};
  const link = [...row.querySelectorAll('a, button')].find(e => e.textContent.trim() === '[Show Markdown]');
  if (!link) return 'no Markdown in row ' + {key};
  link.click();
  return '';
}})()"""
_PICTURES = """[...document.querySelectorAll('img')].filter(i => i.src.startsWith('data:image/png')
              && i.complete && i.naturalWidth > 0).length"""


def _debugger_url(port: int, deadline_s: float) -> str:
    end = time.time() + deadline_s
    while True:
        try:
            with urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list", timeout=2) as response:
                pages = [t for t in json.load(response) if t.get("type") == "page"]
            if pages:
                return pages[0]["webSocketDebuggerUrl"]
        except OSError:
            pass
        if time.time() > end:
            raise SystemExit("ui_screenshot: Chromium's DevTools endpoint did not come up")
        time.sleep(0.3)


async def _shoot(ws_url: str, url: str, out: Path, wait_s: float, markdown_key: str | None = None) -> int:
    async with websockets.connect(ws_url, max_size=64 << 20) as ws:
        counter = 0

        async def call(method: str, **params):
            nonlocal counter
            counter += 1
            await ws.send(json.dumps({"id": counter, "method": method, "params": params}))
            while True:
                message = json.loads(await ws.recv())
                if message.get("id") == counter:
                    return message.get("result", {})

        await call("Page.enable")
        await call("Page.navigate", url=url)
        await asyncio.sleep(wait_s)
        await call("Runtime.evaluate", expression=_DISMISS)
        await asyncio.sleep(1.5)
        if markdown_key is not None:
            clicked = await call("Runtime.evaluate", expression=_SHOW_MARKDOWN.format(key=json.dumps(markdown_key)),
                                 returnByValue=True)
            problem = clicked.get("result", {}).get("value", "no answer")
            if problem:
                raise SystemExit(f"ui_screenshot: {url}: {problem}")
            await asyncio.sleep(2.0)
        shot = await call("Page.captureScreenshot", format="png")
        out.write_bytes(base64.b64decode(shot["data"]))
        pictures = await call("Runtime.evaluate", expression=_PICTURES, returnByValue=True)
        return int(pictures.get("result", {}).get("value", 0))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("url")
    parser.add_argument("out", type=Path)
    parser.add_argument("--size", default="1600x1000", help="window size, WIDTHxHEIGHT pixels")
    parser.add_argument("--wait", type=float, default=8.0, help="seconds for the page to load before the shot")
    parser.add_argument("--port", type=int, default=9333, help="Chromium's DevTools port")
    parser.add_argument("--show-markdown", default=None, metavar="KEY",
                        help="open the Markdown (a picture) of the metadata entry KEY before the shot")
    parser.add_argument("--expect-images", type=int, default=0, metavar="N",
                        help="exit with status 1 when the page shows fewer than N inline PNG pictures")
    args = parser.parse_args()
    browser = shutil.which("chromium") or shutil.which("chromium-browser")
    if browser is None:
        raise SystemExit("ui_screenshot: no chromium on PATH (Debian: apt-get install chromium)")
    width, height = (int(v) for v in args.size.lower().split("x"))
    with tempfile.TemporaryDirectory() as profile:
        proc = subprocess.Popen([browser, "--headless", "--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--hide-scrollbars",
                                 f"--window-size={width},{height}", f"--remote-debugging-port={args.port}",
                                 f"--user-data-dir={profile}", "about:blank"],
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        try:
            pictures = asyncio.run(_shoot(_debugger_url(args.port, 30.0), args.url, args.out, args.wait,
                                          args.show_markdown))
        finally:
            proc.terminate()
            proc.wait(timeout=20)
    print(f"wrote {args.out} ({args.out.stat().st_size // 1024} KiB), pictures: {pictures}")
    if pictures < args.expect_images:
        raise SystemExit(f"ui_screenshot: {args.url} shows {pictures} picture(s), expected at least {args.expect_images}")


if __name__ == "__main__":
    main()
