"""Check that the relative links of README.md, CHANGELOG.md, docs/*.md and research/*.md resolve: files
exist, anchors name a heading.

    python scripts/check_doc_links.py [FILE.md ...]

Inline links and images (`[text](target)`, `![alt](target)`) and reference definitions
(`[name]: target`) are checked; web links (http, https, mailto) are not. An anchor (`#...`) into a
Markdown file must be the GitHub slug of one of its headings. Code blocks and code spans are skipped.
Prints one line per broken link and exits with 1 if there is any.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
INLINE = re.compile(r"!?\[(?:[^\[\]]|\[[^\]]*\])*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")
REFERENCE = re.compile(r"^\s{0,3}\[[^\]]+\]:\s*<?(\S+?)>?(?:\s+.*)?$")
HEADING = re.compile(r"^#{1,6}\s+(.*?)\s*#*\s*$")


def _prose(text: str) -> list[str]:
    """The file's lines with fenced code blocks blanked and code spans removed."""
    out, fenced = [], False
    for line in text.splitlines():
        if line.lstrip().startswith(("```", "~~~")):
            fenced = not fenced
            out.append("")
            continue
        out.append("" if fenced else re.sub(r"`[^`]*`", "", line))
    return out


def slugs(path: Path) -> set[str]:
    """GitHub's anchors for the headings of a Markdown file."""
    seen: dict[str, int] = {}
    found = set()
    fenced = False
    for line in path.read_text(encoding="utf-8").splitlines():
        if line.lstrip().startswith(("```", "~~~")):
            fenced = not fenced
            continue
        match = None if fenced else HEADING.match(line)
        if not match:
            continue
        slug = re.sub(r"[^\w\- ]", "", match.group(1).strip().lower()).replace(" ", "-")
        count = seen.get(slug, 0)
        seen[slug] = count + 1
        found.add(slug if count == 0 else f"{slug}-{count}")
    return found


def broken_links(path: Path) -> list[str]:
    problems = []
    for number, line in enumerate(_prose(path.read_text(encoding="utf-8")), start=1):
        targets = INLINE.findall(line)
        ref = REFERENCE.match(line)
        if ref:
            targets.append(ref.group(1))
        for target in targets:
            if re.match(r"^[a-z][a-z0-9+.-]*:", target, re.IGNORECASE):
                continue  # http:, https:, mailto: ...
            file_part, _, anchor = target.partition("#")
            resolved = (path.parent / file_part).resolve() if file_part else path
            where = f"{path.relative_to(ROOT)}:{number}: {target}"
            if not resolved.exists():
                problems.append(f"{where}: no such file")
            elif anchor and resolved.suffix == ".md" and anchor not in slugs(resolved):
                problems.append(f"{where}: no heading with that anchor")
    return problems


def documents() -> list[Path]:
    """The pages whose links are checked: the README, the changelog, the user docs and the research notes."""
    top = [path for path in (ROOT / "README.md", ROOT / "CHANGELOG.md") if path.is_file()]
    return [*top, *sorted((ROOT / "docs").glob("*.md")), *sorted((ROOT / "research").glob("*.md"))]


def main(argv: list[str]) -> int:
    files = [Path(a).resolve() for a in argv] or documents()
    problems = [p for f in files for p in broken_links(f)]
    print("\n".join(problems) if problems else f"{len(files)} files, every relative link resolves")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
