"""Small helpers that write the self-contained HTML pages of ``analyse`` and ``compare``.

Pages need no network: the stylesheet (``templates/page.css``) and scripts
(``templates/*.js``) are inlined, figures are PNG files in the same folder as
the page (relative links, so the folder can be moved or zipped whole), data
is JSON inside ``<script type="application/json">``.
"""

from __future__ import annotations

import html
import json
from importlib import resources
from typing import Any

from sitframe.analysis.results import Table

__all__ = ["esc", "json_script", "page", "table_html", "template"]


def esc(value: Any) -> str:
    """``value`` as text, escaped for HTML."""
    return html.escape(str(value), quote=True)


def template(name: str) -> str:
    """The text of ``sitframe/analysis/templates/<name>`` (package data)."""
    return (resources.files("sitframe.analysis") / "templates" / name).read_text(
        encoding="utf-8")


def json_script(element_id: str, data: Any) -> str:
    """``data`` as a ``<script type="application/json">`` element (``</`` escaped)."""
    text = json.dumps(data, separators=(",", ":"), allow_nan=False).replace("</", "<\\/")
    return f'<script type="application/json" id="{esc(element_id)}">{text}</script>'


def table_html(t: Table, *, table_id: str | None = None,
               highlight: list[bool] | None = None) -> str:
    """A :class:`~sitframe.analysis.results.Table` as an HTML table with caption and notes.

    ``highlight`` marks rows (class ``sig``), e.g. significant differences.
    """
    head = "".join(f"<th>{esc(c)}</th>" for c in t.columns)
    num, body = t.numeric(), []
    for j, r in enumerate(t.cells()):
        cls = ' class="sig"' if highlight and highlight[j] else ""
        body.append(f"<tr{cls}>" + "".join(f'<td{" class=num" if n else ""}>{esc(c)}</td>'
                                           for c, n in zip(r, num, strict=True)) + "</tr>")
    ident = f' id="{esc(table_id)}"' if table_id else ""
    notes = "".join(f'<p class="note">{esc(n)}</p>' for n in t.notes)
    return (f'<div class="tablewrap"><table{ident}><caption>{esc(t.title)}</caption>'
            f"<thead><tr>{head}</tr></thead><tbody>{''.join(body)}</tbody></table>"
            f"{notes}</div>")


def page(title: str, body: str, *, scripts: tuple[str, ...] = ()) -> str:
    """A complete HTML document with the inlined stylesheet and ``scripts`` (JS source)."""
    js = "".join(f"<script>{s}</script>" for s in scripts)
    return ("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
            "<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">"
            "<link rel=\"icon\" href=\"data:,\">"
            f"<title>{esc(title)}</title><style>{template('page.css')}</style></head>"
            f"<body>{body}{js}</body></html>\n")
