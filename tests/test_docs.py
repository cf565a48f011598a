"""The documentation site (mkdocs.yml): every public name has an API entry, and the site
builds with `mkdocs build --strict` (a broken link, an unresolved cross-reference in a rendered
docstring or a missing object fails it)."""

import re
import subprocess
import sys
import types

import pytest
from pathlib import Path

import jaxrod
import jaxrod.design
import jaxrod.paper
import jaxrod.sweeps

ROOT = Path(__file__).resolve().parent.parent


def _public(module):
    return {n for n in dir(module) if not n.startswith("_") and not isinstance(getattr(module, n), types.ModuleType)}


def _entries():
    text = "\n".join(p.read_text() for p in (ROOT / "docs" / "api").glob("*.md"))
    return set(re.findall(r"^::: (\S+)$", text, flags=re.M))


def _resolve(path):
    parts = path.split(".")
    obj = __import__(parts[0])
    for p in parts[1:]:
        obj = getattr(obj, p)
    return obj


def test_every_public_name_has_an_api_entry():
    entries = _entries()
    rendered = {id(_resolve(e)) for e in entries if not isinstance(_resolve(e), (int, float, str, tuple, dict))}
    for module in (jaxrod, jaxrod.design, jaxrod.paper, jaxrod.sweeps):
        for name in sorted(_public(module)):
            path = f"{module.__name__}.{name}"
            value = getattr(module, name)
            # the same object under another public path (jaxrod.sweep is jaxrod.sweeps.sweep) counts
            same = not isinstance(value, (int, float, str, tuple, dict)) and id(value) in rendered
            assert path in entries or same, f"{path} has no entry in docs/api/"


def test_api_entries_name_public_objects():
    for e in _entries():
        assert not any(p.startswith("_") for p in e.split(".")), e
        _resolve(e)


def test_site_builds_strictly(tmp_path):
    r = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(tmp_path / "site")],
                       cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    site = tmp_path / "site"
    for page in ("index.html", "api/branches/index.html", "examples/01_getting_started/index.html",
                 "mathjax/tex-chtml.js"):
        assert (site / page).is_file(), page
    html = (site / "api" / "branches" / "index.html").read_text()
    assert 'id="jaxrod.snap_angles"' in html and "arithmatex" in html
    # the command line page carries every subcommand's help
    from jaxrod.cli._main import _build_parser

    sub = next(a for a in _build_parser()._actions if a.__class__.__name__ == "_SubParsersAction")
    cli = (site / "cli" / "index.html").read_text()
    for name in sub.choices:
        assert f'id="jaxrod-{name}"' in cli, name


@pytest.mark.slow  # a browser (~30 s); needs Debian's chromium: apt-get install chromium
def test_site_in_a_browser(tmp_path):
    """docs/check_site.py: the home page, an API page and an example page load in headless
    Chromium with no JavaScript error, failed request or broken image; screenshots written."""
    sys.path.insert(0, str(ROOT / "docs"))
    try:
        import check_site
    finally:
        sys.path.pop(0)
    assert check_site._browser() is not None, "the browser check needs Debian's chromium: apt-get install chromium"
    site = tmp_path / "site"
    check_site.build(site)
    problems = check_site.check(site, tmp_path / "shots")
    assert problems == [], problems
    for page in check_site.PAGES:
        shot = tmp_path / "shots" / (page.replace("/", "_").replace(".html", "") + ".png")
        assert shot.stat().st_size > 10_000, shot
