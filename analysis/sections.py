"""A report section as plain data (paragraphs, tables, figures), typeset the same way in the PDF and in
results.md, so that a section is computed once and written twice."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

PARA_SIZE = 9.5  # pt
TABLE_START_MM = 30  # a table's heading row (up to five lines at 8 pt) and its first row


@dataclass
class Block:
    """A paragraph (`text`), a table (`rows`, heading row first; `widths` relative), or a figure (`path`,
    a PNG, with `text` as its caption)."""

    text: str = ""
    rows: list[list[str]] | None = None
    widths: list[float] | None = None
    path: Path | None = None


@dataclass
class Section:
    title: str
    blocks: list[Block] = field(default_factory=list)

    def para(self, text: str) -> Section:
        self.blocks.append(Block(text=text))
        return self

    def table(self, rows: list[list[str]], widths: list[float] | None = None) -> Section:
        self.blocks.append(Block(rows=rows, widths=widths))
        return self

    def figure(self, path: Path, caption: str) -> Section:
        self.blocks.append(Block(text=caption, path=Path(path)))
        return self


def markdown_lines(section: Section, out_dir: Path) -> list[str]:
    """The section in Markdown; figure links relative to `out_dir`, where results.md is written."""
    lines = [f"## {section.title}", ""]
    for block in section.blocks:
        if block.rows is not None:
            head, *body = block.rows
            lines += ["| " + " | ".join(head) + " |", "|---" + "|---:" * (len(head) - 1) + "|"]
            lines += ["| " + " | ".join(cell.replace("\n", " ") for cell in row) + " |" for row in body]
        elif block.path is not None:
            lines.append(f"![{block.text}]({block.path.relative_to(out_dir)})")
        else:
            lines.append(block.text)
        lines.append("")
    return lines


def write_pdf_section(w: Any, section: Section) -> None:
    """The section through the report's writer (`analysis.report.ReportWriter`)."""
    w.section(section.title)
    for block, after in zip(section.blocks, [*section.blocks[1:], None], strict=True):
        if block.rows is not None:
            w.table(block.rows, col_widths=block.widths, size=8, align="LEFT")
        elif block.path is not None:
            w.image(block.path, caption=block.text)
        else:
            if after is not None and after.rows is not None:
                # A paragraph that leads a table stays on the page of the table's heading and first rows.
                w.keep(w.para_height(block.text, PARA_SIZE) + TABLE_START_MM)
            w.para(block.text, size=PARA_SIZE)
