"""The certificate file: HTML or PDF, chosen by the output's suffix."""

from __future__ import annotations

from pathlib import Path

from ..errors import InputError
from .certificate_html import certificate_html
from .certificate_pdf import certificate_pdf

FORMATS = {".html": "HTML", ".htm": "HTML", ".pdf": "PDF"}


def check_certificate_path(path) -> str:
    """The certificate's format by the output's suffix (``.html``, ``.htm``, ``.pdf``)."""
    suffix = Path(path).suffix.lower()
    if suffix not in FORMATS:
        raise InputError(f"{path}: the certificate is written as HTML (.html) or PDF (.pdf), "
                         f"by the suffix; found {suffix or 'none'!r}")
    return FORMATS[suffix]


def certificate_bytes(doc: dict, path) -> bytes:
    """The certificate file's bytes, HTML or PDF by ``path``'s suffix."""
    if check_certificate_path(path) == "PDF":
        return certificate_pdf(doc)
    return certificate_html(doc).encode("utf-8")


def write_certificate(doc: dict, path, *, force: bool = False) -> None:
    """Write the certificate file, HTML or PDF by ``path``'s suffix, atomically."""
    from ..files.outputs import atomic_write

    data = certificate_bytes(doc, path)
    with atomic_write(Path(path), "wb", force=force) as fh:
        fh.write(data)
