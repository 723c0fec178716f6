"""The README, the changelog, docs/*.md and research/*.md link to files and headings that exist
(scripts/check_doc_links.py)."""

from __future__ import annotations

import importlib.util

from tests.helpers import REPO_ROOT


def _checker():
    spec = importlib.util.spec_from_file_location("check_doc_links", REPO_ROOT / "scripts" / "check_doc_links.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_readme_and_docs_links_resolve():
    checker = _checker()
    files = checker.documents()
    assert REPO_ROOT / "README.md" in files and REPO_ROOT / "research" / "study.md" in files
    assert [p for f in files for p in checker.broken_links(f)] == []


def test_checker_finds_a_missing_file_and_a_missing_anchor(tmp_path):
    checker = _checker()
    checker.ROOT = tmp_path
    (tmp_path / "a.md").write_text("# Title\n\n## Some part\n")
    page = tmp_path / "b.md"
    page.write_text("[ok](a.md#some-part) [gone](nope.md) [bad](a.md#other) `[code](x.md)`\n\n"
                    "```\n[fenced](y.md)\n```\n[ref]: a.md#title\n")
    assert checker.broken_links(page) == ["b.md:1: nope.md: no such file",
                                          "b.md:1: a.md#other: no heading with that anchor"]
