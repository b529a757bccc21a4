"""Sphinx extension of the calstudy book: no progress bars, one copy of each script, the book's
own CSS.

The Monte Carlo engine draws its progress bars (tqdm) on stderr; in a notebook kernel stderr is
the cell's output, so an executed notebook holds the bars. The book shows what a notebook
computed, not how long it took: when a notebook is read, the progress lines are dropped from its
stderr outputs (what else a cell wrote to stderr, a warning, stays).

Jupyter Book 1 loads ``sphinx_thebe`` and ``sphinx_togglebutton``, whose inline scripts end up
twice in every page's head (the themes add them again while pages are written); the second
``const THEBE_JS_URL`` is a console error ("Identifier 'THEBE_JS_URL' has already been
declared"). When the build finishes, every page keeps only the first copy of each identical
script line of its head. ``_static/calstudy.css`` styles the claims page (badges, table).

Pages stay light: the theme's icon script (``fontawesome.js``, 1.45 MB, for a dozen icons) is
dropped from every page and ``calstudy.css`` draws those icons as characters; the favicon is
also copied to the site's root (``/favicon.ico``, which browsers ask for over HTTP). The
notebooks offered for download (``_sources/``) lose their progress lines as the pages do.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

#: One redraw of a tqdm bar ("label:  40%|####      | 80/200 [00:01<00:02, 57.1trial/s]") or a
#: plain "trial k/n" progress line.
PROGRESS = re.compile(
    r"^[^\n]*\d+%\|[^\n]*\|\s*\d+/\d+\s*\[[^\n]*\]\s*$|^\s*trial\s+\d+\s*/\s*\d+\b[^\n]*$",
    re.IGNORECASE,
)


def strip_progress(text: str) -> str:
    """``text`` of a stream output without its progress redraws (tqdm bars and "trial k/n"
    lines, separated by carriage returns or newlines)."""
    kept = [
        part
        for part in re.split(r"(?<=[\r\n])", text)
        if not PROGRESS.match(part.strip()) and part != "\r"  # a bar's carriage returns too
    ]
    out = "".join(kept)
    return "" if not out.strip() else out


def strip_notebook_progress(source: str) -> str:
    """The JSON text of a notebook with progress removed from its stderr outputs (an output
    left empty is dropped); the text unchanged if it holds none."""
    nb = json.loads(source)
    changed = False
    for cell in nb.get("cells", []):
        outputs = []
        for out in cell.get("outputs", []):
            if out.get("output_type") == "stream" and out.get("name") == "stderr":
                text = out.get("text", "")
                text = "".join(text) if isinstance(text, list) else text
                stripped = strip_progress(text)
                if stripped != text:
                    changed = True
                    if not stripped:
                        continue
                    out = {**out, "text": stripped}
            outputs.append(out)
        if "outputs" in cell:
            cell["outputs"] = outputs
    return json.dumps(nb, ensure_ascii=False, indent=1) if changed else source


def _source_read(app, docname, source) -> None:
    path = Path(app.env.doc2path(docname))
    if path.suffix == ".ipynb":
        source[0] = strip_notebook_progress(source[0])


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


#: A script line of the head that no page needs (the icons are characters in calstudy.css).
_ICON_SCRIPT = re.compile(r"^[ \t]*<script[^>]*scripts/fontawesome\.js[^>]*></script>[ \t]*\n?",
                          re.MULTILINE)


def lighten(text: str) -> str:
    """``text`` of a page with repeated head scripts and the icon script removed."""
    return _ICON_SCRIPT.sub("", dedupe_head(text))


def _finish_pages(app, exception) -> None:
    if exception is not None or app.builder.format != "html":
        return
    out = Path(app.outdir)
    for page in out.rglob("*.html"):
        text = page.read_text(encoding="utf-8")
        fixed = lighten(text)
        if fixed != text:
            page.write_text(fixed, encoding="utf-8")
    for notebook in (out / "_sources").rglob("*.ipynb"):
        text = notebook.read_text(encoding="utf-8")
        fixed = strip_notebook_progress(text)
        if fixed is not text:
            notebook.write_text(fixed, encoding="utf-8")
    favicon = out / "_static" / "favicon.ico"
    if favicon.is_file():
        (out / "favicon.ico").write_bytes(favicon.read_bytes())


def setup(app):
    app.connect("source-read", _source_read)
    app.connect("build-finished", _finish_pages)
    app.add_css_file("calstudy.css")
    return {"parallel_read_safe": True, "parallel_write_safe": True}
