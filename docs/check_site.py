#!/usr/bin/env python
"""Open the documentation site in a real browser: build it, serve it over HTTP, and load the
home page, an API page and an example page in headless Chromium (Debian's `chromium`
package, driven by Playwright), failing if a page raises a JavaScript error, a request fails or
answers with an error status, or an image does not load; a full-page screenshot of each is
written.

    python docs/check_site.py                      # build into a temporary folder, screenshots to site-check/
    python docs/check_site.py --site DIR --out DIR # an already built site

Needs the `docs` extra, `playwright` (`pip install playwright`; its own browser download is
not used) and Debian's `chromium` (`apt-get install chromium`). Exit status 0 when every page
loaded cleanly, 1 otherwise (each problem printed), 2 when the browser is missing.
"""

from __future__ import annotations

import argparse
import functools
import http.server
import shutil
import subprocess
import sys
import tempfile
import threading
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PAGES = ("index.html", "api/branches/index.html", "examples/01_getting_started/index.html")
"""The pages opened: the home page, an API page (math and cross-references), an example (a
notebook with its figures)."""


def build(site: Path) -> None:
    subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(site)], cwd=ROOT,
                   check=True, capture_output=True)


def _browser() -> str | None:
    for name in ("chromium", "chromium-browser"):
        path = shutil.which(name)
        if path:
            return path
    return None


class _Quiet(http.server.SimpleHTTPRequestHandler):
    def log_message(self, *args):
        pass


def check(site: Path, out: Path, pages=PAGES) -> list[str]:
    """Every problem seen while loading `pages` of the built `site` (empty: all clean)."""
    from playwright.sync_api import sync_playwright

    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), functools.partial(_Quiet, directory=str(site)))
    threading.Thread(target=server.serve_forever, daemon=True).start()
    base = f"http://127.0.0.1:{server.server_address[1]}/"
    out.mkdir(parents=True, exist_ok=True)
    problems = []
    try:
        with sync_playwright() as pw:
            browser = pw.chromium.launch(executable_path=_browser(), args=["--no-sandbox"])
            for page_path in pages:
                page = browser.new_page(viewport={"width": 1280, "height": 900})
                seen = []
                page.on("pageerror", lambda e, seen=seen: seen.append(f"JavaScript error: {e}"))
                page.on("requestfailed", lambda r, seen=seen: seen.append(f"request failed: {r.url} ({r.failure})"))
                page.on("response", lambda r, seen=seen: r.status >= 400 and seen.append(f"HTTP {r.status}: {r.url}"))
                response = page.goto(base + page_path, wait_until="networkidle")
                if response is None or not response.ok:
                    seen.append(f"the page itself did not load ({None if response is None else response.status})")
                broken = page.evaluate("""() => Array.from(document.images)
                    .filter(img => !(img.complete && img.naturalWidth > 0)).map(img => img.src)""")
                seen += [f"image did not load: {src}" for src in broken]
                images = page.evaluate("() => document.images.length")
                page.screenshot(path=str(out / (page_path.replace("/", "_").replace(".html", "") + ".png")),
                                full_page=True)
                problems += [f"{page_path}: {s}" for s in seen]
                print(f"{page_path}: {len(seen)} problems, {images} images", flush=True)
                page.close()
            browser.close()
    finally:
        server.shutdown()
    return problems


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--site", type=Path, help="an already built site (default: build one)")
    ap.add_argument("--out", type=Path, default=Path("site-check"), help="where the screenshots go")
    args = ap.parse_args(argv)
    if _browser() is None:
        print("chromium not found: apt-get install chromium", file=sys.stderr)
        return 2
    with tempfile.TemporaryDirectory() as tmp:
        site = args.site
        if site is None:
            site = Path(tmp) / "site"
            build(site)
        problems = check(site, args.out)
    for p in problems:
        print(p, file=sys.stderr)
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
