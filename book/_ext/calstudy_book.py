"""Sphinx extension of the calstudy book: one copy of each script, the book's own CSS.

Jupyter Book 1 loads ``sphinx_thebe`` and ``sphinx_togglebutton``, whose inline scripts end up
twice in every page's head (the themes add them again while pages are written); the second
``const THEBE_JS_URL`` is a console error ("Identifier 'THEBE_JS_URL' has already been
declared"). When the build finishes, every page keeps only the first copy of each identical
script line of its head. ``_static/calstudy.css`` styles the claims page (badges, table).
"""

from __future__ import annotations

from pathlib import Path


def dedupe_head(text: str) -> str:
    """``text`` with repeated identical ``<script ...>`` lines of its ``<head>`` removed."""
    head_end = text.find("</head>")
    if head_end < 0:
        return text
    seen, kept = set(), []
    for line in text[:head_end].splitlines(keepends=True):
        key = line.strip()
        if key.startswith("<script") and key.endswith("</script>"):
            if key in seen:
                continue
            seen.add(key)
        kept.append(line)
    return "".join(kept) + text[head_end:]


def _dedupe_pages(app, exception) -> None:
    if exception is not None or app.builder.format != "html":
        return
    for page in Path(app.outdir).rglob("*.html"):
        text = page.read_text(encoding="utf-8")
        fixed = dedupe_head(text)
        if fixed != text:
            page.write_text(fixed, encoding="utf-8")


def setup(app):
    app.connect("build-finished", _dedupe_pages)
    app.add_css_file("calstudy.css")
    return {"parallel_read_safe": True, "parallel_write_safe": True}
