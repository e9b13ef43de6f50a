"""A tiny document model rendered both as Markdown and as a standalone HTML page.

A report is a list of blocks (headings, paragraphs, bullet lists, tables, images, and raw
HTML with a Markdown stand-in). Inline text may use four bits of Markdown, which the HTML
renderer converts: ``**bold**``, ```code```, ``![alt](path)`` images (also inside table
cells) and ``[text](path)`` links.
"""

from __future__ import annotations

import html
import re
from collections.abc import Sequence
from dataclasses import dataclass, field


@dataclass
class Block:
    """One block of a document.

    Attributes:
        kind: ``heading``, ``text``, ``list``, ``table``, ``image`` or ``html``.
        text: heading or paragraph text, an image's alt text, or the Markdown of an
            ``html`` block.
        level: heading level (1 = title).
        items: bullet items of a list.
        header: column names of a table.
        rows: table rows, each as long as ``header``.
        path: relative path of an image.
        html: the HTML of an ``html`` block.
    """

    kind: str
    text: str = ""
    level: int = 2
    items: list[str] = field(default_factory=list)
    header: list[str] = field(default_factory=list)
    rows: list[list[str]] = field(default_factory=list)
    path: str = ""
    html: str = ""


def heading(text: str, level: int = 2) -> Block:
    """A heading block."""
    return Block("heading", text=text, level=level)


def text(content: str) -> Block:
    """A paragraph block."""
    return Block("text", text=content)


def bullets(items: Sequence[str]) -> Block:
    """A bullet list block."""
    return Block("list", items=list(items))


def table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> Block:
    """A table block; every row has ``len(header)`` cells."""
    return Block("table", header=list(header), rows=[list(row) for row in rows])


def image(path: str, alt: str) -> Block:
    """An image block (``path`` relative to the document)."""
    return Block("image", text=alt, path=path)


def raw(html_text: str, markdown: str = "") -> Block:
    """HTML for the page (an interactive figure), with ``markdown`` standing for it in Markdown."""
    return Block("html", text=markdown, html=html_text)


def _cell(value: str) -> str:
    return value.replace("|", "\\|").replace("\n", " ")


def markdown_table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    """A GitHub-flavoured Markdown table."""
    lines = ["| " + " | ".join(_cell(h) for h in header) + " |"]
    lines.append("|" + "|".join("---" for _ in header) + "|")
    lines += ["| " + " | ".join(_cell(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)


def to_markdown(blocks: Sequence[Block]) -> str:
    """Render blocks as Markdown."""
    parts = []
    for block in blocks:
        if block.kind == "heading":
            parts.append("#" * block.level + " " + block.text)
        elif block.kind == "text":
            parts.append(block.text)
        elif block.kind == "list":
            parts.append("\n".join(f"- {item}" for item in block.items))
        elif block.kind == "table":
            parts.append(markdown_table(block.header, block.rows))
        elif block.kind == "image":
            parts.append(f"![{block.text}]({block.path})")
        elif block.kind == "html" and block.text:
            parts.append(block.text)
    return "\n\n".join(parts) + "\n"


_IMAGE = re.compile(r"!\[([^\]]*)\]\(([^)]+)\)")
_LINK = re.compile(r"(?<![!\w\]])\[([^\]]*)\]\(([^)\s]+)\)")
_BOLD = re.compile(r"\*\*(.+?)\*\*")
_CODE = re.compile(r"`([^`]+)`")


def inline_html(content: str) -> str:
    """Escape text; convert ``**bold**``, ```code```, ``![alt](path)`` and ``[text](path)``."""
    escaped = html.escape(content, quote=False)
    escaped = _IMAGE.sub(r'<img src="\2" alt="\1">', escaped)
    escaped = _LINK.sub(r'<a href="\2">\1</a>', escaped)
    escaped = _BOLD.sub(r"<b>\1</b>", escaped)
    return _CODE.sub(r"<code>\1</code>", escaped)


_STYLE = (
    "body{font-family:sans-serif;max-width:1400px;margin:2em auto;padding:0 1em}"
    "table{border-collapse:collapse;margin:1em 0;font-size:90%}"
    "th,td{border:1px solid #ccc;padding:3px 8px;text-align:center}"
    "td img{max-width:320px}img{max-width:100%}"
)


def to_html(blocks: Sequence[Block], title: str) -> str:
    """Render blocks as a standalone HTML page."""
    body = []
    for block in blocks:
        if block.kind == "heading":
            body.append(f"<h{block.level}>{inline_html(block.text)}</h{block.level}>")
        elif block.kind == "text":
            body.append(f"<p>{inline_html(block.text)}</p>")
        elif block.kind == "list":
            items = "".join(f"<li>{inline_html(item)}</li>" for item in block.items)
            body.append(f"<ul>{items}</ul>")
        elif block.kind == "table":
            head = "".join(f"<th>{inline_html(h)}</th>" for h in block.header)
            rows = "".join(
                "<tr>" + "".join(f"<td>{inline_html(c)}</td>" for c in row) + "</tr>"
                for row in block.rows
            )
            body.append(f"<table><tr>{head}</tr>{rows}</table>")
        elif block.kind == "image":
            body.append(
                f'<p><img src="{html.escape(block.path)}" alt="{html.escape(block.text)}"></p>'
            )
        elif block.kind == "html":
            body.append(block.html)
    return (
        f'<!DOCTYPE html>\n<html><head><meta charset="utf-8"><title>{html.escape(title)}</title>'
        f"<style>{_STYLE}</style></head><body>\n" + "\n".join(body) + "\n</body></html>\n"
    )
