"""The book as a reader sees it: every page opened in headless Chromium (``make check-book``).

The book is built into a temporary folder from the notebooks executed at their CI values
(:mod:`booksite`; the session's ``ci_runs``, shared with ``test_notebooks.py``); then every
page is loaded in Chromium at 1366 x 900 (:data:`DESKTOP`; :mod:`browser`) and checked:

- no console error, no request leaving the machine, no absolute path of the build machine;
- all math typeset by the shipped MathJax (no raw ``$``, ``\\(`` or ``\\[`` left in the text),
  every image loaded, with an alt text that describes it (not a file path, not a bare name);
- on every page of the table of contents (:data:`FIT_COLUMN`) nothing wider than the article
  column and no table cell holding more than its width (code listings scroll by the theme's
  design and are not counted; tables, outputs, figures and equations are);
- nothing a notebook prints that a reader should not meet: progress bars or "trial k/n" lines,
  raw ``NaN`` cells, object reprs (``PosixPath(``, ``<... object at 0x...>``, ``dtype:``);
  generated text written with ± and µm;
- every link inside the book reaches its page and anchor; the claims page has a badge in its
  verdict's colour per claim and links every computed claim to a section of its notebook;
  one search box (no second header bar), no script twice in a page's head, page titles
  without the book's name twice;
- results first: the claims table's header and first 8 claims in the first screen; every
  paper chapter opens with a verdict box and a figure with a numbered caption that its text
  refers to; glued values in the body's weight; no raw identifier (``0p3``, ``_mm:``,
  ``t2 ``, a claim id) outside code; figure text at least 10 px as shown (the PNG's smallest
  font size, recorded by ``io.results.write_figure``, at its dpi and shown width);
- light pages: a favicon; at most 1.5 MB of files loaded besides the page's own images and
  MathJax, and at most 1.3 MB of MathJax on a page with formulas.

Every page is loaded again at a phone's 390 x 844 (:data:`PHONE`): no page scrolls sideways,
no word breaks inside a table cell (at either size), the claims are cards and the first shows
whole. Screenshots of the claims page and the hybrid chapter at both sizes go to
``book/_build/screenshots/`` (git-ignored) for a reviewer.

Without Chromium the tests fail and say how to install it.
"""

from __future__ import annotations

import re
from pathlib import Path
from urllib.parse import unquote, urlparse

import pytest
import yaml
from booksite import build_ci_book, pages
from browser import INSTALL_HINT, Chromium, find_chromium

from calstudy.claims import claim_register
from calstudy.core.paths import REPO_ROOT, RESULTS_DIR
from calstudy.io.book import PAPERS
from calstudy.io.claims_cells import VERDICT_COLOURS
from calstudy.io.results import FONT_KEY, read_claims

pytestmark = pytest.mark.book



def _toc_pages() -> list[str]:
    """The HTML page of every file of ``book/_toc.yml``, in book order."""

    def files(node):
        if isinstance(node, dict):
            own = [node[k] for k in ("root", "file") if isinstance(node.get(k), str)]
            return own + [f for v in node.values() for f in files(v)]
        if isinstance(node, list):
            return [f for v in node for f in files(v)]
        return []

    toc = yaml.safe_load((REPO_ROOT / "book" / "_toc.yml").read_text())
    return [f"{f}.html" for f in files(toc)]


#: Pages on which no element may be wider than the article column: every page of the book
#: (code listings scroll by the theme's design and are not counted; tables, outputs, figures
#: and equations are).
FIT_COLUMN = tuple(_toc_pages())
#: Window sizes a reader opens the book at (CSS px): a laptop and a phone.
DESKTOP = (1366, 900)
PHONE = (390, 844)
#: Pages photographed for the reviewer at both sizes, and the stem of their screenshots.
SCREENSHOTS = {
    "claims.html": "claims",
    "hybrid.html": "chapter-hybrid",
}
SCREENSHOT_DIR = REPO_ROOT / "book" / "_build" / "screenshots"
#: The paper chapters: each opens with a verdict box and a numbered figure.
CHAPTERS = tuple(f"{paper}.html" for paper in PAPERS)
#: Claims rows of the table visible without scrolling at DESKTOP.
FIRST_SCREEN_CLAIMS = 8
#: Smallest figure text on the page at 100 % (CSS px).
MIN_FIGURE_TEXT_PX = 10.0
#: Assets a page loads besides its own images and MathJax (bytes): HTML, CSS, scripts, fonts.
MAX_PAGE_ASSETS = 1_500_000
#: What MathJax adds on a page with formulas (its one bundle, ``tex-chtml.js``, 1.16 MB, and
#: the fonts it loads).
MAX_MATHJAX = 1_300_000
#: Text a reader must not meet outside code: raw column patterns and claim ids.
RAW_PATTERNS = (r"\d+p\d", r"_mm:", r"\bt\d ", r"\b(?:hybrid|selfcal|binocular|dualarm)\.[a-z_]+\b")

# Runs in the page after MathJax and the images settled; returns what the checks read.
_INSPECT = r"""
(() => {
  const art = document.querySelector('article.bd-article') || document.querySelector('main')
    || document.body;
  // code a reader reads as code: input cells and code blocks of the prose (not cell outputs)
  const isCode = e => !!e.closest('.cell_input, pre, code, .highlight')
    && !e.closest('.cell_output');
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
  // what the page shows as text and output: the article without its input cells
  const shown = art.cloneNode(true);
  shown.querySelectorAll('.cell_input, script, style, mjx-assistive-mml').forEach(e => e.remove());
  // text nodes joined by spaces, so that table cells do not run together
  const walker = document.createTreeWalker(shown, NodeFilter.SHOW_TEXT);
  const parts = [];
  while (walker.nextNode()) { parts.push(walker.currentNode.nodeValue); }
  const shownText = parts.join(' ');
  const find = (res) => {
    const hits = [];
    for (const re of res) {
      for (const m of shownText.matchAll(re)) {
        hits.push(shownText.slice(Math.max(0, m.index - 25), m.index + 45).replace(/\s+/g, ' '));
      }
    }
    return hits;
  };
  const noise = find([/trial\s+\d+\s*\/\s*\d+/gi, /\d+\s*%\|/g, /%\|/g, /\|[█▉▊▋▌▍▎▏ ]{3,}\|/g,
                      /\d+(\.\d+)?\s*(it\/s|s\/it)\]/g]);
  const reprs = find([/\b(?:Pure)?(?:Posix|Windows)Path\(/g, /<[A-Za-z_][\w.]* object at 0x/g,
                      /<Figure size [\d.]+x[\d.]+ with \d+ Axes>/g, /<matplotlib\.[\w.]+/g,
                      /(^|[^.\w])[A-Z][a-z]\w*\([a-z_]+=/g, /\barray\(\[/g,
                      /\bdtype: \w+/g]);
  // text the book generates: cell outputs on a notebook page, all prose elsewhere
  const outputs = [...art.querySelectorAll('.cell_output')].map(e => e.textContent).join(' ');
  const generated = art.querySelector('.cell_output, .cell') ? outputs : text;
  const typography = [];
  for (const m of generated.matchAll(/\+-|\d\s?um\b/g)) {
    typography.push(generated.slice(Math.max(0, m.index - 25), m.index + 25)
      .replace(/\s+/g, ' '));
  }
  const nanCells = [...art.querySelectorAll('td, th')]
    .filter(c => /(^|[^\w])(nan|NaN|<NA>|NaT)([^\w]|$)/.test(c.textContent.trim()))
    .map(c => c.textContent.trim().slice(0, 40));
  const body = document.body.cloneNode(true);
  body.querySelectorAll('script, style').forEach(e => e.remove());
  const alts = [...document.querySelectorAll('[alt], [title]')]
    .map(e => (e.getAttribute('alt') || '') + ' ' + (e.getAttribute('title') || ''));
  const broken = [...document.images]
    .filter(i => !(i.complete && i.naturalWidth > 0))
    .map(i => i.getAttribute('src'));
  const pathLike = /^\S*\.(png|jpe?g|svg|gif|webp)$|^(\.\.?\/|\/|_images\/|data:)/i;
  const imgAlts = [...document.images].map(i => (i.getAttribute('alt') || '').trim())
    .filter(a => a);
  const badAlt = [...document.images].filter(i => {
    const alt = (i.getAttribute('alt') || '').trim();
    return !alt || alt === i.getAttribute('src') || pathLike.test(alt);
  }).map(i => `alt ${JSON.stringify(i.getAttribute('alt'))} of `
    + (i.getAttribute('src') || '').slice(0, 60));
  // dropdowns measured open (what one click shows must fit too), closed again afterwards
  const closed = [...art.querySelectorAll('details:not([open])')];
  closed.forEach(d => { d.open = true; });
  const box = art.getBoundingClientRect();
  const wide = [];
  const seen = new Set();
  for (const e of art.querySelectorAll('*')) {
    if (e.closest('mjx-assistive-mml') || isCode(e)) continue;
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
  closed.forEach(d => { d.open = false; });
  const links = [...art.querySelectorAll('a[href]')].map(a => a.href)
    .filter(h => h.startsWith('file:'));
  const ids = [...document.querySelectorAll('[id]')].map(e => e.id);
  const badges = [...art.querySelectorAll('.verdict')].map(e => ({
    cls: e.className, colour: getComputedStyle(e).backgroundColor, text: e.textContent}));
  const headScripts = [...document.head.querySelectorAll('script')].map(e => e.outerHTML);
  const searches = [...document.querySelectorAll('input[type=search], .search-button-field, '
    + 'form.bd-search')].filter(e => e.getBoundingClientRect().height > 0
    && !e.closest('.search-button__wrapper')).length;
  return {text: body.textContent + ' ' + alts.join(' '), raw_math: raw, broken: broken,
          wide: wide, column: box.width, noise: noise, reprs: reprs, nan_cells: nanCells,
          bad_alt: badAlt, alts: imgAlts, typography: typography, links: links, ids: ids,
          badges: badges, title: document.title, head_scripts: headScripts,
          searches: searches};
})()
"""


# Runs after _INSPECT: what a reader meets at the window's size (first screen, sideways
# scrolling, broken words, weights, figures, the chapter's opening, the assets loaded).
_READER = r"""
(() => {
  const art = document.querySelector('article.bd-article') || document.querySelector('main')
    || document.body;
  const rect = e => { const r = e.getBoundingClientRect();
    return {top: r.top + window.scrollY, bottom: r.bottom + window.scrollY, width: r.width}; };
  const table = art.querySelector('table.claims');
  const claims = table ? {
    header: table.tHead ? rect(table.tHead) : null,
    header_shown: table.tHead ? getComputedStyle(table.tHead).display !== 'none' : false,
    rows: [...table.querySelectorAll('tr.claim')].map(rect),
    display: (table.querySelector('tr.claim') ? getComputedStyle(
      table.querySelector('tr.claim')).display : ''),
  } : null;
  // a word split over two lines inside a table cell (a break at a hyphen or slash is a break
  // between words)
  const broken = [];
  for (const cell of art.querySelectorAll('td, th')) {
    if (broken.length > 20) break;
    if (cell.getBoundingClientRect().width === 0 || cell.closest('pre, .cell_input')) continue;
    const walker = document.createTreeWalker(cell, NodeFilter.SHOW_TEXT);
    while (walker.nextNode()) {
      const node = walker.currentNode;
      for (const m of node.nodeValue.matchAll(/[^\s\-‐–—\/]{2,}/g)) {
        const range = document.createRange();
        range.setStart(node, m.index);
        range.setEnd(node, m.index + m[0].length);
        const tops = new Set([...range.getClientRects()].filter(r => r.width > 0)
          .map(r => Math.round(r.top)));
        if (tops.size > 1) { broken.push(`${m[0]} in "${cell.textContent.trim().slice(0, 50)}"`); }
      }
    }
  }
  const bold = [...art.querySelectorAll('.pasted-text, .pasted-inline')].filter(e =>
    +getComputedStyle(e).fontWeight >= 600 && +getComputedStyle(e.parentElement).fontWeight < 600
  ).map(e => e.textContent.trim().slice(0, 60));
  const shown = art.cloneNode(true);
  shown.querySelectorAll('.cell_input, pre, code, .highlight, script, style, mjx-container, '
    + 'mjx-assistive-mml').forEach(e => e.remove());
  const walker = document.createTreeWalker(shown, NodeFilter.SHOW_TEXT);
  const parts = [];
  while (walker.nextNode()) { parts.push(walker.currentNode.nodeValue); }
  const images = [...art.querySelectorAll('img')].filter(i => i.getBoundingClientRect().width > 0)
    .map(i => ({src: i.currentSrc || i.src, shown: i.getBoundingClientRect().width,
                natural: i.naturalWidth, alt: (i.getAttribute('alt') || '').slice(0, 50)}));
  const boxes = [...art.querySelectorAll('.verdict-box')].map(b =>
    b.querySelectorAll('.verdict').length);
  const numbered = [...art.querySelectorAll('figure')].map(f =>
    (f.querySelector('.caption-number') || {textContent: ''}).textContent.trim())
    .filter(n => /^Fig\.?\s*\d+/.test(n));
  const numrefs = [...art.querySelectorAll('a.reference span.std-numref, a.reference.internal')]
    .map(a => a.textContent.trim()).filter(s => /^Fig\.?\s*\d+/.test(s));
  return {
    scroll_width: document.documentElement.scrollWidth, inner_width: window.innerWidth,
    inner_height: window.innerHeight, claims: claims, broken: broken, bold: bold,
    glued: art.querySelectorAll('.pasted-text, .pasted-inline').length,
    text: parts.join(' '), images: images, boxes: boxes, numbered: numbered, numrefs: numrefs,
    icons: [...document.querySelectorAll('link[rel~="icon"]')].map(l => l.href),
  };
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
    with Chromium(chromium_binary, width=DESKTOP[0], height=DESKTOP[1]) as browser:
        for page in pages(html):
            rel = page.relative_to(html).as_posix()
            report = browser.open(page.as_uri())
            out[rel] = {"report": report, **browser.evaluate(_INSPECT),
                        "reader": browser.evaluate(_READER)}
            if rel in SCREENSHOTS:
                out[rel]["screenshot"] = browser.screenshot(
                    SCREENSHOT_DIR / f"{SCREENSHOTS[rel]}-{DESKTOP[0]}.png")
    return out


@pytest.fixture(scope="session")
def phone(chromium_binary, build) -> dict[str, dict]:
    """Every page opened once at the phone's size: ``{relative path: what _READER read}``."""
    html, _ = build
    out = {}
    with Chromium(chromium_binary, width=PHONE[0], height=PHONE[1]) as browser:
        for page in pages(html):
            rel = page.relative_to(html).as_posix()
            browser.open(page.as_uri())
            out[rel] = {"reader": browser.evaluate(_READER)}
            if rel in SCREENSHOTS:
                out[rel]["screenshot"] = browser.screenshot(
                    SCREENSHOT_DIR / f"{SCREENSHOTS[rel]}-{PHONE[0]}.png")
    return out


def _rgb(colour: str) -> str:
    """``"#1a7f37"`` as the browser reports it: ``"rgb(26, 127, 55)"``."""
    r, g, b = (int(colour[i : i + 2], 16) for i in (1, 3, 5))
    return f"rgb({r}, {g}, {b})"


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
    assert page in seen, f"{page} is in the table of contents but was not built"
    wide = seen[page]["wide"]
    assert not wide, f"{page}: {len(wide)} element(s) overflow the column or their cell:\n" + (
        "\n".join(wide[:20])
    )


def test_no_progress_noise(seen):
    """Progress bars and "trial k/n" lines go to the terminal, not into the book."""
    assert not any(i["noise"] for i in seen.values()), _failures(
        seen, lambda _, i: [f"progress output: {s!r}" for s in i["noise"]]
    )


def test_no_nan_cells(seen):
    """A missing value is an em dash with its reason (io.display), never a raw NaN."""
    assert not any(i["nan_cells"] for i in seen.values()), _failures(
        seen, lambda _, i: [f"{len(i['nan_cells'])} table cell(s) read {i['nan_cells'][0]!r}"]
        if i["nan_cells"] else []
    )


def test_no_object_reprs(seen):
    """No path objects, object reprs, raw arrays or Series footers in what a page shows."""
    assert not any(i["reprs"] for i in seen.values()), _failures(
        seen, lambda _, i: [f"object repr: {s!r}" for s in i["reprs"]]
    )


def test_every_image_has_a_descriptive_alt(seen):
    """Every image's alt text describes it: present, not a file path, a phrase of at least
    five words (not just the figure's file name)."""

    def problems(_, info):
        found = [f"image without a describing alt text: {s}" for s in info["bad_alt"]]
        found += [f"alt text too short to describe the image: {a!r}" for a in info["alts"]
                  if len(a.split()) < 5]
        return found

    assert not any(problems(p, i) for p, i in seen.items()), _failures(seen, problems)


def test_generated_text_is_typeset(seen):
    """Generated text writes ± and µm, not "+-" and "um"."""
    assert not any(i["typography"] for i in seen.values()), _failures(
        seen, lambda _, i: [f"untypeset: {s!r}" for s in i["typography"]]
    )


def test_internal_links_resolve(seen, build):
    """Every link to a page of the book reaches an existing file and, with a fragment, an
    element with that id on the page (the claims page links to notebook sections)."""
    html, _ = build
    ids = {page: set(info["ids"]) for page, info in seen.items()}

    def problems(_, info):
        found = []
        for link in info["links"]:
            url, _, fragment = link.partition("#")
            target = Path(unquote(urlparse(url).path))
            if not target.exists():
                found.append(f"link to a missing file: {link}")
                continue
            try:
                rel = target.relative_to(html).as_posix()
            except ValueError:
                found.append(f"link out of the book: {link}")
                continue
            if fragment and rel in ids and unquote(fragment) not in ids[rel]:
                found.append(f"link to a missing anchor: {rel}#{fragment}")
        return found

    assert not any(problems(p, i) for p, i in seen.items()), _failures(seen, problems)


def test_claims_page_badges_and_section_links(seen):
    """The claims page: one coloured badge per claim and per verdict count, each in its
    verdict's colour; every claim computed links to a section of its notebook."""
    info = seen["claims.html"]
    expected = {v.replace(" ", "-"): _rgb(c) for v, c in VERDICT_COLOURS.items()}
    register = claim_register()
    assert len(info["badges"]) >= len(register)
    for badge in info["badges"]:
        verdict = badge["cls"].split("verdict-")[-1]
        assert badge["colour"] == expected[verdict], badge
        assert badge["text"].replace(" ", "-") == verdict, badge
    sections = [link for link in info["links"] if "/notebooks/" in link and "#" in link]
    computed = read_claims(RESULTS_DIR / "claims.csv")
    assert len(sections) == len(computed), sections


def test_one_header_bar_and_no_duplicate_scripts(seen):
    """The pydata theme's second header bar (with a second search box) stays off, and no
    script is written twice into a page's head."""

    def problems(page, info):
        found = []
        if page != "search.html" and info["searches"] > 1:
            found.append(f"{info['searches']} search boxes")
        dupes = {s for s in info["head_scripts"] if info["head_scripts"].count(s) > 1}
        found += [f"script twice in the head: {s[:80]}" for s in sorted(dupes)]
        return found

    assert not any(problems(p, i) for p, i in seen.items()), _failures(seen, problems)


def test_page_titles(seen):
    """A page title names the page, then the book: never the book twice."""
    bad = {p: i["title"] for p, i in seen.items()
           if len(set(i["title"].split(" — "))) < len(i["title"].split(" — "))}
    assert not bad, bad


def test_screenshots_written(seen, phone):
    for size, views in ((DESKTOP, seen), (PHONE, phone)):
        for page, stem in SCREENSHOTS.items():
            assert page in views, f"{page} was not built"
            shot = views[page]["screenshot"]
            assert shot == SCREENSHOT_DIR / f"{stem}-{size[0]}.png"
            assert shot.stat().st_size > 10_000


def test_claims_table_in_the_first_screen(seen, phone):
    """At 1366 x 900 the claims table's header and its first 8 claims show without scrolling;
    on a phone the claims are cards (one block each) and the first one shows whole."""
    desk = seen["claims.html"]["reader"]
    claims = desk["claims"]
    assert claims is not None, "the claims page has no table.claims"
    height = desk["inner_height"]
    assert claims["header_shown"] and claims["header"]["bottom"] <= height, claims["header"]
    assert len(claims["rows"]) >= FIRST_SCREEN_CLAIMS
    last = claims["rows"][FIRST_SCREEN_CLAIMS - 1]
    assert last["bottom"] <= height, (
        f"claim {FIRST_SCREEN_CLAIMS} ends {last['bottom']:.0f} px down in a {height} px window")
    mobile = phone["claims.html"]["reader"]["claims"]
    assert mobile["display"] == "block", f"claims shown as {mobile['display']}, not cards"
    first = mobile["rows"][0]
    assert first["bottom"] <= PHONE[1], f"the first claim card ends {first['bottom']:.0f} px down"


def test_no_page_scrolls_sideways(seen, phone):
    def problems(_, info):
        r = info["reader"]
        return ([f"{r['scroll_width']} px wide in a {r['inner_width']} px window"]
                if r["scroll_width"] > r["inner_width"] else [])

    for views in (seen, phone):
        assert not any(problems(p, i) for p, i in views.items()), _failures(views, problems)


def test_no_word_broken_inside_a_table_cell(seen, phone):
    for size, views in ((DESKTOP, seen), (PHONE, phone)):
        assert not any(i["reader"]["broken"] for i in views.values()), _failures(
            views, lambda _, i, w=size[0]: [f"at {w} px, word broken: {s}"
                                            for s in i["reader"]["broken"]]
        )


def test_glued_values_in_the_body_weight(seen):
    glued = sum(i["reader"]["glued"] for i in seen.values())
    assert glued, "no page holds a glued value: the check reads nothing"
    assert not any(i["reader"]["bold"] for i in seen.values()), _failures(
        seen, lambda _, i: [f"bold glued value: {s!r}" for s in i["reader"]["bold"]]
    )


def test_no_raw_identifiers_in_page_text(seen):
    """Outside code, no raw column pattern (``0p3``, ``_mm:``, ``t2 ``) and no claim id: the
    label map (calstudy.core.labels) writes them as words."""
    def problems(_, info):
        text = info["reader"]["text"]
        return [f"raw identifier: {text[max(0, m.start() - 30):m.end() + 20]!r}"
                for pattern in RAW_PATTERNS for m in re.finditer(pattern, text)][:5]

    assert not any(problems(p, i) for p, i in seen.items()), _failures(seen, problems)


def _png(src: str, html: Path):
    """The PNG an image shows: from its data URI or its file."""
    import base64
    import io

    from PIL import Image

    if src.startswith("data:"):
        return Image.open(io.BytesIO(base64.b64decode(src.split(",", 1)[1])))
    return Image.open(Path(unquote(urlparse(src).path)))


def test_figure_text_at_least_10_px(seen, build):
    """Every figure's smallest text, as the page shows it at 1366 px: its size in points
    (written into the PNG by io.results.write_figure) at the PNG's dpi, scaled by the shown
    over the natural width."""
    html, _ = build

    def problems(_, info):
        found = []
        for img in info["reader"]["images"]:
            png = _png(img["src"], html)
            if png.format != "PNG":
                continue
            pt = png.info.get(FONT_KEY)
            if pt is None:
                found.append(f"no font size recorded in the figure {img['alt']!r}")
                continue
            dpi = png.info.get("dpi", (72, 72))[0]
            px = float(pt) / 72 * dpi * img["shown"] / img["natural"]
            if px < MIN_FIGURE_TEXT_PX:
                found.append(f"text {px:.1f} px in the figure {img['alt']!r}")
        return found

    assert not any(problems(p, i) for p, i in seen.items()), _failures(seen, problems)


def test_every_chapter_opens_with_verdicts_and_a_numbered_figure(seen):
    for page in CHAPTERS:
        r = seen[page]["reader"]
        assert r["boxes"] and min(r["boxes"]) > 0, f"{page}: no verdict box with badges"
        assert r["numbered"], f"{page}: no figure with a numbered caption"
        assert r["numrefs"], f"{page}: the text refers to no figure by its number"


def test_favicon(seen, build):
    html, _ = build
    assert (html / "favicon.ico").is_file(), "no favicon.ico at the site's root"

    def problems(_, info):
        icons = info["reader"]["icons"]
        if not icons:
            return ["no icon link"]
        return [f"icon missing: {i}" for i in icons
                if not Path(unquote(urlparse(i).path)).is_file()]

    assert not any(problems(p, i) for p, i in seen.items()), _failures(seen, problems)


_IMAGE = (".png", ".jpg", ".jpeg", ".gif", ".svg", ".webp", ".ico")
_DATA_IMAGE = re.compile(r"data:image/[a-z+]+;base64,[A-Za-z0-9+/=]+")


def page_assets(info) -> dict[str, int]:
    """Bytes of each file a page requested besides images: the page (without the images it
    holds as data URIs), CSS, scripts, fonts, MathJax's files."""
    sizes = {}
    for url in info["report"].requests:
        if not url.startswith("file:"):
            continue
        path = Path(unquote(urlparse(url).path))
        if path.suffix.lower() in _IMAGE or not path.is_file():
            continue
        size = path.stat().st_size
        if path.suffix == ".html":
            text = path.read_text(encoding="utf-8")
            size -= sum(len(m.group(0).encode()) for m in _DATA_IMAGE.finditer(text))
        sizes[path.as_posix()] = size
    return sizes


def test_page_assets_under_budget(seen):
    """Each page loads at most 1.5 MB besides its own images, and MathJax at most 1.3 MB more
    on a page with formulas."""
    assert all(page_assets(i) for i in seen.values()), "a page loaded no file: nothing measured"

    def problems(_, info):
        sizes = page_assets(info)
        mathjax = sum(v for k, v in sizes.items() if "/_static/mathjax/" in k)
        total = sum(sizes.values()) - mathjax
        found = []
        if total > MAX_PAGE_ASSETS:
            top = sorted(sizes.items(), key=lambda kv: -kv[1])[:3]
            found.append(f"{total / 1e6:.2f} MB of assets besides MathJax; largest "
                         + ", ".join(f"{Path(k).name} {v / 1e6:.2f} MB" for k, v in top))
        if mathjax > MAX_MATHJAX:
            found.append(f"MathJax loads {mathjax / 1e6:.2f} MB")
        return found

    assert not any(problems(p, i) for p, i in seen.items()), _failures(seen, problems)
