"""Small HTML building blocks of the calibration report: cells, tables, badges, figures.

Every piece of text goes through :func:`escape`, so text from a user's files is shown
literally: markup escaped, control characters (an ESC in a sensor's name) written as
the terminal shows them.
"""

from __future__ import annotations

import base64
import html

from ..errors import printable


def escape(text: object, keep: str = "\n") -> str:
    """``text`` for HTML: control characters escaped as repr does (but ``keep``'s: a
    note's own line breaks, which HTML folds), then markup.  A user's name in a heading or
    the title keeps none (``keep=""``): its newline is shown, not folded into a space."""
    return html.escape(printable(text, keep=keep, spaces=True))


def worse(value: float | None, initial: float | None) -> bool:
    """True when a method did worse than the initial data (the paper's bold cells)."""
    return value is not None and initial is not None and value > initial


def cell(text: str, worse: bool = False) -> str:
    if worse:
        return f'<td class="worse"><span aria-label="worse than initial">▲</span> {escape(text)}</td>'
    return f"<td>{escape(text)}</td>"


def table(tid: str, caption: str, head: list[str], rows: list[str]) -> str:
    """``head`` holds ready ``<tr>`` rows, ``rows`` ready ``<tr>`` body rows."""
    return (f'<table id="{tid}"><caption>{escape(caption)}</caption>\n<thead>{"".join(head)}'
            f'</thead>\n<tbody>{"".join(rows)}</tbody></table>\n')


def scrolled(html_table: str) -> str:
    """A table wider than the page, in a box that scrolls sideways (its cells unwrapped)."""
    return f'<div class="scroll">{html_table}</div>\n'


def tr(*cells: str) -> str:
    return "<tr>" + "".join(cells) + "</tr>\n"


def th(text: str, span: int = 1, rowspan: int = 1) -> str:
    attrs = (f' colspan="{span}"' if span > 1 else "") + (f' rowspan="{rowspan}"' if rowspan > 1 else "")
    return f"<th{attrs}>{escape(text)}</th>"


def note(text: str) -> str:
    return f'<p class="note">{escape(text)}</p>\n'


def badge_span(status: str) -> str:
    """A pass/warn badge: the word and the symbol carry it, the colour only helps."""
    ok = status == "pass"
    return f'<span class="badge {"pass" if ok else "warn"}">{"✔ PASS" if ok else "⚠ WARN"}</span>'


def badge(status: str) -> str:
    return f"<td>{badge_span(status)}</td>"


def figure_html(fid: str, png: bytes, alt: str, caption: str) -> str:
    data = base64.b64encode(png).decode("ascii")
    return (f'<figure id="{fid}"><img alt="{escape(alt)}" src="data:image/png;base64,{data}">'
            f"<figcaption>{escape(caption)}</figcaption></figure>\n")


CSS = """
body{font-family:system-ui,-apple-system,"Segoe UI",sans-serif;max-width:1200px;margin:1.5em auto;
padding:0 1em;color:#111;line-height:1.4}
h1{font-size:1.6em;margin-bottom:.2em}h2{border-bottom:2px solid #444;padding-bottom:.2em;margin-top:1.8em}
table{border-collapse:collapse;margin:.8em 0 1.2em;font-size:.92em}
caption{text-align:left;font-weight:600;padding:.3em 0;white-space:nowrap}
th,td{border:1px solid #999;padding:.25em .6em;text-align:right}th{background:#eee}
td:first-child{text-align:left}
.mono{font-family:ui-monospace,monospace;font-size:.85em;text-align:left}
td.worse{font-weight:700;background:#fdd;border:2px solid #000}
.badge{display:inline-block;padding:.05em .5em;border-radius:.6em;font-weight:700;border:1.5px solid}
.badge.pass{color:#064;border-color:#064}.badge.warn{color:#930;border-color:#930;background:#fec}
figure{margin:1em 0}figure img{max-width:100%;height:auto;border:1px solid #ccc}
figcaption{font-size:.9em;color:#333}.note{color:#333;font-style:italic}
.scroll{overflow-x:auto}.scroll td{white-space:nowrap}
@media print{body{max-width:none}h2{page-break-before:auto}figure,table{page-break-inside:avoid}
.scroll{overflow:visible}}
"""
