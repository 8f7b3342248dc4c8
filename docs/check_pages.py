"""Look at the built docs in a headless browser: a full-page screenshot of each page at a
desktop and a phone width, and a count of the code blocks whose text is wider than their
box (a reader sees it cut off at the right edge until scrolling sideways).

Needs the site (``mkdocs build``), Playwright (``pip install playwright``) and a Chromium
(Debian's ``chromium`` package, or ``playwright install chromium``)::

    mkdocs build && python docs/check_pages.py tutorial-design-study index notebooks/02_design_optimisation

Writes ``PAGE_WIDTH.png`` and ``pages.json`` (per page and width: code blocks, how many
overflow, and the first characters of each that does) into ``--out`` (default
``runs/pages``); exits 1 when a code block overflows at the desktop width.
"""

from __future__ import annotations

import argparse
import functools
import http.server
import json
import shutil
import sys
import threading
from pathlib import Path

WIDTHS = {"desktop": (1280, 900), "phone": (390, 844)}
#: what each code block reports: its width and the width of its text, CSS pixels
MEASURE = """() => [...document.querySelectorAll('pre')].map(p => p.querySelector('code') || p).map(c => ({
    client: c.clientWidth, scroll: c.scrollWidth, text: c.innerText.slice(0, 60)}))"""


def chromium() -> str | None:
    """A Chromium executable on this machine, or None (Playwright's own then)."""
    for name in ("chromium", "chromium-browser", "google-chrome"):
        path = shutil.which(name)
        if path:
            return path
    return None


class _Quiet(http.server.SimpleHTTPRequestHandler):
    def log_message(self, *args):
        pass


def serve(site: Path) -> tuple[http.server.ThreadingHTTPServer, str]:
    handler = functools.partial(_Quiet, directory=str(site))
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    return server, f"http://127.0.0.1:{server.server_address[1]}"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("pages", nargs="+", help="pages by path in the site, without index.html (index: the home page)")
    ap.add_argument("--site", type=Path, default=Path("site"))
    ap.add_argument("--out", type=Path, default=Path("runs/pages"))
    args = ap.parse_args(argv)
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        print("needs Playwright: pip install playwright", file=sys.stderr)
        return 2
    if not (args.site / "index.html").exists():
        print(f"no site in {args.site}: run mkdocs build first", file=sys.stderr)
        return 2
    args.out.mkdir(parents=True, exist_ok=True)
    server, base = serve(args.site)
    report, failed = {}, False
    flags = ["--no-sandbox", "--disable-gpu", "--disable-background-networking", "--disable-component-update"]
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=chromium(), args=flags)
        for page_name in args.pages:
            url = f"{base}/" if page_name == "index" else f"{base}/{page_name.strip('/')}/"
            for label, (w, h) in WIDTHS.items():
                page = browser.new_page(viewport={"width": w, "height": h})
                response = page.goto(url, wait_until="networkidle")
                if response is None or response.status != 200:
                    raise SystemExit(f"{url}: HTTP {None if response is None else response.status}")
                blocks = page.evaluate(MEASURE)
                over = [b for b in blocks if b["scroll"] > b["client"] + 1]
                name = f"{page_name.replace('/', '_')}_{label}.png"
                page.screenshot(path=str(args.out / name), full_page=True)
                report.setdefault(page_name, {})[label] = {
                    "code_blocks": len(blocks),
                    "overflowing": len(over),
                    "overflowing_starts": [b["text"] for b in over],
                    "screenshot": name,
                }
                failed |= label == "desktop" and bool(over)
                print(f"{page_name} ({label}, {w} px): {len(blocks)} code blocks, {len(over)} wider than their box")
                page.close()
        browser.close()
    server.shutdown()
    (args.out / "pages.json").write_text(json.dumps(report, indent=2) + "\n")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
