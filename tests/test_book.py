"""The book as a reader sees it: every page opened in headless Chromium (``make check-book``).

The book is built into a temporary folder from the notebooks executed at their CI values
(:mod:`booksite`; the session's ``ci_runs``, shared with ``test_notebooks.py``); then every
page is loaded in Chromium at a 1,400 px window (:mod:`browser`) and checked: no console error,
no request leaving the machine, all math typeset by the shipped MathJax (no raw ``$``, ``\\(``
or ``\\[`` left in the text), every image loaded, no absolute path of the build machine in the
text; on the pages of :data:`FIT_COLUMN` no element is wider than the article column and no
table cell holds more than its width. Screenshots of the claims page and a notebook page go to
``book/_build/screenshots/`` (git-ignored) for a reviewer.

Without Chromium the tests fail and say how to install it.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from booksite import build_ci_book, pages
from browser import INSTALL_HINT, Chromium, find_chromium

from calstudy.core.paths import REPO_ROOT

pytestmark = pytest.mark.book

#: Pages on which no element may be wider than the article column.
FIT_COLUMN = ("claims.html",)
#: Pages photographed for the reviewer, and the file names of their screenshots.
SCREENSHOTS = {
    "claims.html": "claims.png",
    "notebooks/04_binocular_correction.html": "notebook-04.png",
}
SCREENSHOT_DIR = REPO_ROOT / "book" / "_build" / "screenshots"
WIDTH = 1400

# Runs in the page after MathJax and the images settled; returns what the checks read.
_INSPECT = r"""
(() => {
  const art = document.querySelector('article.bd-article') || document.querySelector('main')
    || document.body;
  const prose = art.cloneNode(true);
  prose.querySelectorAll('pre, code, script, style, textarea, mjx-container, .highlight')
    .forEach(e => e.remove());
  const text = prose.textContent;
  const raw = [];
  for (const re of [/\$\$[^$]+\$\$/g, /\$[^$\s][^$\n]{0,200}?\$/g, /\\[()\[\]]/g, /\\begin\{/g]) {
    for (const m of text.matchAll(re)) {
      raw.push(text.slice(Math.max(0, m.index - 30), m.index + 40).replace(/\s+/g, ' '));
    }
  }
  const body = document.body.cloneNode(true);
  body.querySelectorAll('script, style').forEach(e => e.remove());
  const alts = [...document.querySelectorAll('[alt], [title]')]
    .map(e => (e.getAttribute('alt') || '') + ' ' + (e.getAttribute('title') || ''));
  const broken = [...document.images]
    .filter(i => !(i.complete && i.naturalWidth > 0))
    .map(i => i.getAttribute('src'));
  const box = art.getBoundingClientRect();
  const wide = [];
  const seen = new Set();
  for (const e of art.querySelectorAll('*')) {
    if (e.closest('mjx-assistive-mml')) continue;
    const r = e.getBoundingClientRect();
    if (r.width === 0 || r.height === 0) continue;
    if (r.right > box.right + 1 || r.left < box.left - 1) {
      if (e.parentElement && seen.has(e.parentElement)) { seen.add(e); continue; }
      seen.add(e);
      const name = e.tagName.toLowerCase() + (e.className && typeof e.className === 'string'
        ? '.' + e.className.trim().split(/\s+/).join('.') : '');
      wide.push(`${name} ${Math.round(r.width)} px wide, ${Math.round(r.left - box.left)}`
        + `..${Math.round(r.right - box.left)} px in a ${Math.round(box.width)} px column`);
    }
  }
  for (const cell of art.querySelectorAll('td, th')) {
    if (cell.scrollWidth > cell.clientWidth + 1) {
      wide.push(`a ${cell.tagName.toLowerCase()} holds ${cell.scrollWidth} px in `
        + `${cell.clientWidth} px: ${cell.textContent.trim().slice(0, 60)}`);
    }
  }
  return {text: body.textContent + ' ' + alts.join(' '), raw_math: raw, broken: broken,
          wide: wide, column: box.width};
})()
"""


@pytest.fixture(scope="session")
def chromium_binary() -> str:
    path = find_chromium()
    if path is None:
        pytest.fail(f"the browser check needs Chromium and found none; install it with: "
                    f"{INSTALL_HINT}")
    return path


@pytest.fixture(scope="session")
def build(tmp_path_factory, ci_runs) -> tuple[Path, Path]:
    """``(html folder, temporary root)`` of the book built from the CI-valued notebook runs."""
    root = tmp_path_factory.mktemp("book-check")
    return build_ci_book(root, ci_runs), root


@pytest.fixture(scope="session")
def seen(chromium_binary, build) -> dict[str, dict]:
    """Every page opened once: ``{relative path: report and inspection}``."""
    html, _ = build
    out = {}
    with Chromium(chromium_binary, width=WIDTH) as browser:
        for page in pages(html):
            rel = page.relative_to(html).as_posix()
            report = browser.open(page.as_uri())
            out[rel] = {"report": report, **browser.evaluate(_INSPECT)}
            if rel in SCREENSHOTS:
                out[rel]["screenshot"] = browser.screenshot(SCREENSHOT_DIR / SCREENSHOTS[rel])
    return out


def _failures(seen: dict, problems) -> str:
    lines = [f"{page}: {p}" for page, info in seen.items() for p in problems(page, info)]
    return f"{len(lines)} problem(s):\n" + "\n".join(lines[:40])


def test_every_page_opened(seen):
    assert "intro.html" in seen and "claims.html" in seen
    notebooks = [p for p in seen if p.startswith("notebooks/")]
    assert notebooks, "no notebook page was built"


def test_no_console_errors(seen):
    assert not any(i["report"].errors for i in seen.values()), _failures(
        seen, lambda _, i: i["report"].errors
    )


def test_no_request_leaves_the_machine(seen):
    assert not any(i["report"].remote_requests for i in seen.values()), _failures(
        seen, lambda _, i: i["report"].remote_requests
    )


def test_math_is_typeset(seen):
    assert not any(i["raw_math"] for i in seen.values()), _failures(
        seen, lambda _, i: [f"raw math left: {s!r}" for s in i["raw_math"]]
    )


def test_every_image_loads(seen):
    assert not any(i["broken"] for i in seen.values()), _failures(
        seen, lambda _, i: [f"image not loaded: {s}" for s in i["broken"]]
    )


def test_no_absolute_path_of_the_build_machine(seen, build, ci_runs):
    _, root = build
    results = {str(run.results.parent) for run in ci_runs.values()}
    leaks = (str(REPO_ROOT), str(root), *sorted(results))

    def problems(_, info):
        return [f"page text holds {leak}" for leak in leaks if leak in info["text"]]

    assert not any(problems(p, i) for p, i in seen.items()), _failures(seen, problems)


@pytest.mark.parametrize("page", FIT_COLUMN)
def test_nothing_wider_than_the_column(seen, page):
    wide = seen[page]["wide"]
    assert not wide, f"{page}: {len(wide)} element(s) overflow the column or their cell:\n" + (
        "\n".join(wide[:20])
    )


def test_screenshots_written(seen):
    for page, name in SCREENSHOTS.items():
        assert page in seen, f"{page} was not built"
        shot = seen[page]["screenshot"]
        assert shot == SCREENSHOT_DIR / name and shot.stat().st_size > 10_000
