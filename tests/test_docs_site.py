"""The documentation site builds from ``docs/`` (mkdocs, strict: a broken link, a missing page, a docstring
whose parameters do not match its signature fail the build), every page is reachable, and every figure a
page shows exists.  The self-test shows the strict build failing on a page linking to a missing one."""

from __future__ import annotations

import glob
import os
import re
import shutil
import subprocess
import sys

import pytest

pytest.importorskip("mkdocs")
pytest.importorskip("mkdocstrings")

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _build(config, site):
    env = dict(os.environ, NO_MKDOCS_2_WARNING="1")
    return subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "-f", config, "-d", site],
                          capture_output=True, text=True, env=env, cwd=ROOT, timeout=600)


def test_site_builds_strictly_with_every_page_and_figure(tmp_path):
    site = tmp_path / "site"
    run = _build(os.path.join(ROOT, "mkdocs.yml"), str(site))
    assert run.returncode == 0, run.stderr[-3000:]
    with open(os.path.join(ROOT, "mkdocs.yml")) as f:
        config = f.read()
    pages = [os.path.relpath(p, os.path.join(ROOT, "docs")) for p in glob.glob(os.path.join(ROOT, "docs", "**", "*.md"), recursive=True)]
    for page in pages:
        if page.endswith("_params.md"):
            continue  # generated tables, linked from their system's page
        assert page in config, f"docs/{page} is not in the site's navigation"
        html = site / page.replace(".md", "") / "index.html" if not page.endswith("index.md") else site / "index.html"
        assert html.exists(), html
    for html in glob.glob(str(site / "**" / "*.html"), recursive=True):
        with open(html) as f:
            for src in re.findall(r'<img[^>]+src="([^"]+\.png)"', f.read()):
                if not src.startswith("http"):
                    assert os.path.exists(os.path.normpath(os.path.join(os.path.dirname(html), src))), (html, src)


def test_strict_build_fails_on_a_broken_link(tmp_path):
    docs = tmp_path / "docs"
    docs.mkdir()
    (docs / "index.md").write_text("# Home\n\nSee [the missing page](missing.md).\n")
    config = tmp_path / "mkdocs.yml"
    config.write_text(f"site_name: t\ndocs_dir: {docs}\nnav:\n  - Home: index.md\n")
    run = _build(str(config), str(tmp_path / "site"))
    assert run.returncode != 0 and "missing.md" in run.stderr
    shutil.rmtree(tmp_path / "site", ignore_errors=True)
