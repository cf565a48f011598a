"""MkDocs hooks of the documentation site (`mkdocs.yml`).

* `on_startup`: lays out `jaxrod` for the API pages' static analysis (`SOURCE_TREE`).
* `on_page_markdown`: writes every subcommand's `--help` into the command-line page
  (`CLI_MARKER`) and points the pages' repository links at the site's folders (`_LINKS`).
* `on_post_build`: MathJax is served from the site itself, not from a CDN, so that the site
  renders its equations offline and the browser check (`docs/check_site.py`) sees no failed
  request: its files come from the `django-static-mathjax` package (MathJax 3, no Django
  needed; the `docs` extra installs it) and are copied next to the built pages.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

SOURCE_TREE = Path(__file__).resolve().parent.parent / "build" / "docs-src"
"""Where `on_startup` lays out `jaxrod` for the API pages (`paths` in mkdocs.yml)."""

CLI_MARKER = "<!-- cli-reference -->"
"""Where `on_page_markdown` writes every subcommand's `--help` into the command-line page."""

# Pages in docs/ link to the benchmark tables and the notebooks by their paths in the
# repository (so that they resolve on the repository's web page too); on the site, those
# folders are the symlinks docs/bench (../benchmarks) and docs/examples (../notebooks).
_LINKS = (("](../benchmarks/", "bench/"), ("](../notebooks/", "examples/"))


def on_startup(command, dirty, **kwargs):
    """Lay out `jaxrod` as the installed package sees it: the repository's jaxrod/ with
    design/ as its `design` subpackage (pyproject.toml's package-dir mapping, which the API
    pages' static analysis cannot read), as symlinks under `SOURCE_TREE` (build/, ignored by
    git)."""
    repo = SOURCE_TREE.parent.parent
    pkg = SOURCE_TREE / "jaxrod"
    if pkg.exists():
        shutil.rmtree(pkg)
    pkg.mkdir(parents=True)
    for entry in (repo / "jaxrod").iterdir():
        if entry.name != "__pycache__":
            (pkg / entry.name).symlink_to(entry)
    (pkg / "design").symlink_to(repo / "design")


def cli_reference() -> str:
    """Markdown of `jaxrod --help` and every subcommand's `--help`, as the parser prints them."""
    from jaxrod.cli._main import _build_parser

    old = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = "100"  # argparse wraps to the terminal's width
    try:
        parser = _build_parser()
        sub = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")
        parts = ["### jaxrod", "", "```text", parser.format_help().rstrip(), "```", ""]
        for name, p in sub.choices.items():
            parts += [f"### jaxrod {name}", "", "```text", p.format_help().rstrip(), "```", ""]
    finally:
        if old is None:
            os.environ.pop("COLUMNS", None)
        else:
            os.environ["COLUMNS"] = old
    return "\n".join(parts)


def on_page_markdown(markdown, page, config, files, **kwargs):
    if CLI_MARKER in markdown:
        markdown = markdown.replace(CLI_MARKER, cli_reference())
    up = "../" * page.file.src_uri.count("/")
    for old, new in _LINKS:
        markdown = markdown.replace(old, "](" + up + new)
    return markdown


def _mathjax_root() -> Path:
    import importlib.util

    spec = importlib.util.find_spec("mathjax")
    if spec is None or not spec.submodule_search_locations:
        raise RuntimeError("the docs need the django-static-mathjax package: pip install -e '.[docs]'")
    root = Path(next(iter(spec.submodule_search_locations))) / "static" / "mathjax" / "es5"
    if not (root / "tex-chtml.js").is_file():
        raise RuntimeError(f"MathJax not found under {root}")
    return root


def on_post_build(config, **kwargs):
    root = _mathjax_root()
    out = Path(config["site_dir"]) / "mathjax"
    out.mkdir(parents=True, exist_ok=True)
    shutil.copy2(root / "tex-chtml.js", out / "tex-chtml.js")
    fonts = Path("output") / "chtml" / "fonts" / "woff-v2"
    shutil.copytree(root / fonts, out / fonts, dirs_exist_ok=True)
