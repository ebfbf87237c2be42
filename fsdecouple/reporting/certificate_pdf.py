"""The certificate as an A4 PDF: the blocks of :func:`.certificate_html.certificate_blocks`,
laid out by reportlab (pure Python, installs with pip alone).

Text is set in DejaVu Sans, the TrueType font matplotlib ships, embedded (as a
subset) so the file reads the same on any machine; the figures are the HTML's own
PNGs.  Open-source reportlab writes no PDF/A (no XMP metadata or output intent), so
the file is plain PDF 1.4.  ``invariant`` output: the bytes depend on the document
only, not on the time of writing.
"""

from __future__ import annotations

import io
from pathlib import Path
from xml.sax import saxutils

import matplotlib

from ..errors import printable
from .certificate_html import Block, certificate_blocks, u_figure
from .plots import to_png


def escape(text: object) -> str:
    """A user's text for reportlab's paragraph markup: control characters escaped as the
    terminal and the HTML show them (an ESC in a sensor's name), then the markup."""
    return saxutils.escape(printable(text, spaces=True))


FONT, BOLD = "DejaVuSans", "DejaVuSans-Bold"
MARGIN_MM = 12.0


def _fonts() -> None:
    from reportlab.pdfbase import pdfmetrics
    from reportlab.pdfbase.ttfonts import TTFont

    if FONT in pdfmetrics.getRegisteredFontNames():
        return
    ttf = Path(matplotlib.get_data_path()) / "fonts" / "ttf"
    pdfmetrics.registerFont(TTFont(FONT, str(ttf / "DejaVuSans.ttf")))
    pdfmetrics.registerFont(TTFont(BOLD, str(ttf / "DejaVuSans-Bold.ttf")))


def _table(b: Block, width: float, styles) -> list:
    from reportlab.lib import colors
    from reportlab.platypus import Paragraph, Spacer, Table, TableStyle

    n = max([1, len(b.head), *[len(r) for r in b.rows]])
    size = 8.0 if n <= 5 else 6.5 if n <= 9 else 5.6
    cell = styles["cell"].clone("c", fontSize=size, leading=size * 1.2)
    wide = n > 9  # the budget: a regular-weight header so its longest word fits a column
    head = styles["cell"].clone("h", fontName=FONT if wide else BOLD, fontSize=min(size, 5.0)
                                if wide else size, leading=size * 1.2)
    big = styles["cell"].clone("b", fontName=BOLD, fontSize=size + 2, leading=(size + 2) * 1.2)
    data = []
    if b.head:
        data.append([Paragraph(escape(h), head) for h in b.head])
    for row in b.rows:
        data.append([Paragraph(escape(v), big if i == b.emphasis else cell) for i, v in enumerate(row)])
    if b.ident == "identity":
        widths = [0.3 * width, 0.7 * width]
    elif b.ident in ("sources",):
        widths = [0.22 * width, 0.78 * width]
    elif b.ident == "classes":
        widths = [w * width for w in (0.12, 0.12, 0.1, 0.44, 0.22)]
    elif wide:  # the load column needs less than the contributions
        widths = [0.05 * width, *[0.95 * width / (n - 1)] * (n - 1)]
    else:
        widths = [width / n] * n
    t = Table(data, colWidths=widths, repeatRows=1 if b.head else 0, hAlign="LEFT")
    style = [("GRID", (0, 0), (-1, -1), 0.4, colors.grey), ("FONTNAME", (0, 0), (-1, -1), FONT),
             ("VALIGN", (0, 0), (-1, -1), "TOP"),
             ("LEFTPADDING", (0, 0), (-1, -1), 1 if wide else 2),
             ("RIGHTPADDING", (0, 0), (-1, -1), 1 if wide else 2)]
    if b.head:
        style.append(("BACKGROUND", (0, 0), (-1, 0), colors.HexColor("#eeeeee")))
    t.setStyle(TableStyle(style))
    return [Paragraph(escape(b.text), styles["caption"]), t, Spacer(1, 8)]


def certificate_pdf(doc: dict) -> bytes:
    """The certificate as the bytes of an A4 PDF, fonts embedded."""
    from reportlab.lib.pagesizes import A4
    from reportlab.lib.styles import ParagraphStyle
    from reportlab.lib.units import mm
    from reportlab.platypus import Image, PageBreak, Paragraph, SimpleDocTemplate, Spacer

    _fonts()
    base = ParagraphStyle("base", fontName=FONT, bulletFontName=FONT, fontSize=8.5, leading=10.5)
    styles = {"cell": base,
              "title": base.clone("title", fontName=BOLD, fontSize=15, leading=19, spaceAfter=8),
              "h2": base.clone("h2", fontName=BOLD, fontSize=12, leading=15, spaceBefore=4,
                               spaceAfter=6),
              "caption": base.clone("caption", fontName=BOLD, spaceBefore=4, spaceAfter=3),
              "note": base.clone("note", fontName=FONT, textColor="#333333", spaceAfter=4)}
    buf = io.BytesIO()
    page = SimpleDocTemplate(buf, pagesize=A4, leftMargin=MARGIN_MM * mm, rightMargin=MARGIN_MM * mm,
                             topMargin=MARGIN_MM * mm, bottomMargin=MARGIN_MM * mm,
                             title=f"Calibration certificate: {printable(doc['sensor'])}",
                             author="fsdecouple", subject="ISO 376 figures, class and budget",
                             creator=f"fsdecouple {doc.get('fsdecouple_version', '')}",
                             invariant=1,
                             # reportlab starts each page in Helvetica, which would stand
                             # in the file unembedded though no text uses it
                             initialFontName=FONT)
    width = page.width
    story: list = []
    components = 0
    for b in certificate_blocks(doc):
        if b.kind == "title":
            story.append(Paragraph(escape(b.text), styles["title"]))
        elif b.kind == "heading":
            if story and (b.ident != "method" or components):
                story.append(PageBreak())  # each component on its own page, as the HTML prints
            components += b.ident != "method"
            story.append(Paragraph(escape(b.text), styles["h2"]))
        elif b.kind == "note":
            story.append(Paragraph(escape(b.text), styles["note"]))
        elif b.kind == "figure":
            png = to_png(u_figure(doc, b.ident))  # the HTML's own PNG
            story += [Image(io.BytesIO(png), width=width, height=width * 2.6 / 6.0),
                      Paragraph(escape(b.text), styles["note"]), Spacer(1, 6)]
        else:
            story += _table(b, width, styles)
    page.build(story)
    return buf.getvalue()

