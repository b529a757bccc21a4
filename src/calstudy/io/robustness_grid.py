"""The robustness grid of the claims page: claims by inputs, each cell coloured by the
verdicts the claim takes over that input's range.

:func:`read_maps` collects the notebooks' maps (``results/<notebook>/robustness.csv``, written
by :func:`calstudy.core.robustness.robustness_map`); :func:`grid_figure` draws them: one column per
claim with a map, one row per input over whose range at least one claim's verdict changes (screened,
swept, and judged differently at some point), and a last row for all other screened inputs (those
that move a figure but no verdict, and those that do not matter) (inputs down,
so that the figure's text keeps its size in the book's column however many inputs matter). A
cell is split into one stripe per verdict taken over the input's range (the base and the sweep), in
the verdict colours of the book; an input the claim's computation does not read is left
blank.
"""

from __future__ import annotations

import textwrap
from pathlib import Path

import pandas as pd

from calstudy.core.paths import RESULTS_DIR
from calstudy.io.results import notebook_files

#: the map of one notebook, beside its other results
MAP_NAME = "robustness.csv"
#: the row of the inputs over whose range no claim's verdict changes
OTHERS = "other inputs"
#: input names longer than this are wrapped onto lines of at most this many characters
NAME_WIDTH = 26


def read_maps(results_root: str | Path | None = None) -> pd.DataFrame:
    """Every ``<root>/*/robustness.csv`` in one table, with the column ``notebook``.

    Parameters
    ----------
    results_root : path-like, optional
        Folder of the notebooks' result folders; default ``results/``.

    Returns
    -------
    pandas.DataFrame
        The maps (empty, without columns, if none exists).
    """
    root = RESULTS_DIR if results_root in (None, "") else Path(results_root)
    frames = []
    for path in notebook_files(root, MAP_NAME):
        table = pd.read_csv(path, keep_default_na=False, na_values={"value": [""]})
        frames.append(table.assign(notebook=path.parent.name))
    return pd.concat(frames, ignore_index=True) if frames else pd.DataFrame()


def cell_verdicts(maps: pd.DataFrame) -> tuple[dict, list[str], list[str]]:
    """The verdicts each claim takes per input: ``({(claim, input): [verdicts]}, claims,
    inputs that matter (columns, in first-seen order))``: the base verdict and those of the
    input's sweep (points judged by the rule), the inputs that matter to no claim pooled under
    :data:`OTHERS`."""
    claims = list(dict.fromkeys(maps["claim"]))
    taken: dict = {}
    for claim, t in maps.groupby("claim", sort=False):
        base = t.loc[t["stage"] == "base", "verdict"].tolist()
        for label in t.loc[t["stage"] == "screen", "input"].unique():
            # judged points of the input alone (its sweep); a screened end is judged on fewer
            # trials and only tells whether the input is swept
            at = t[(t["input"] == label) & (t["stage"] == "sweep") & (t["error"] == "")]
            taken[(claim, label)] = list(dict.fromkeys([*base, *at["verdict"]]))
    order = list(dict.fromkeys(maps.loc[maps["stage"] == "screen", "input"]))
    changing = [lab for lab in order if any(len(taken.get((c, lab), [])) > 1 for c in claims)]
    cells: dict = {}
    for (claim, label), verdicts in taken.items():
        key = (claim, label if label in changing else OTHERS)
        cells[key] = list(dict.fromkeys([*cells.get(key, []), *verdicts]))
    return cells, claims, [*changing, OTHERS]


def grid_figure(maps: pd.DataFrame, path: str | Path, colours: dict) -> tuple[Path, str]:
    """Draw the grid (module docstring) and write it as a PNG.

    Parameters
    ----------
    maps : pandas.DataFrame
        :func:`read_maps` (at least one map).
    path : path-like
        The PNG to write.
    colours : dict of str to str
        Colour of each verdict.

    Returns
    -------
    (pathlib.Path, str)
        The PNG and a one-sentence description (alt text).
    """
    from matplotlib.figure import Figure
    from matplotlib.patches import Patch, Rectangle

    from calstudy.core.labels import CLAIM_LABELS, claim_label, plain
    from calstudy.io.results import write_figure

    cells, claims, inputs = cell_verdicts(maps)
    # inputs down, claims across: the figure grows in height with the inputs, so its text
    # keeps its size in the book's column however many inputs matter
    input_names = [textwrap.fill(plain(label), NAME_WIDTH) for label in inputs]
    claim_names = [claim_label(c) if c in CLAIM_LABELS else c for c in claims]
    longest = max(len(line) for name in input_names for line in name.splitlines())
    left = 0.3 + 0.07 * longest  # room for the input names, in
    bottom = 0.3 + 0.06 * max(len(name) for name in claim_names)  # the rotated claim names
    cols = max(len(claims), 2)
    cell_w, cell_h = 0.3, 0.36
    width = left + cell_w * cols + 0.3
    height = bottom + 0.7 + cell_h * len(inputs)
    fig = Figure(figsize=(max(width, 4.5), height))
    ax = fig.add_axes(
        (left / max(width, 4.5), bottom / height, cell_w * cols / max(width, 4.5),
         cell_h * len(inputs) / height)
    )
    seen = []
    for j, claim in enumerate(claims):
        for i, label in enumerate(inputs):
            verdicts = cells.get((claim, label), [])
            for k, v in enumerate(verdicts):
                step = 1.0 / len(verdicts)
                box = Rectangle((j + k * step, i), step, 1, color=colours.get(v, "k"), lw=0)
                ax.add_patch(box)
                seen += [v] if v not in seen else []
            ax.add_patch(Rectangle((j, i), 1, 1, fill=False, ec="white", lw=1.5))
    ax.set_xlim(0, len(claims))
    ax.set_ylim(len(inputs), 0)
    ax.set_xticks([j + 0.5 for j in range(len(claims))], claim_names, rotation=60, ha="right",
                  fontsize=9)
    ax.set_yticks([i + 0.5 for i in range(len(inputs))], input_names, fontsize=9)
    ax.tick_params(length=0)
    for side in ax.spines.values():
        side.set_visible(False)
    handles = [Patch(color=colours.get(v, "k"), label=v) for v in seen]
    fig.legend(handles=handles, loc="upper left", ncol=min(len(handles), 2), fontsize=9,
               frameon=False, bbox_to_anchor=(0.01, 0.995))
    path = Path(path)
    write_figure(fig, path)
    conditional = sum(
        any(len(cells.get((c, lab), [])) > 1 for lab in inputs) for c in claims
    )
    alt = (
        f"A grid of {len(claims)} claims by the {len(inputs) - 1} inputs over whose range a "
        f"verdict changes and the other inputs: a cell in one colour keeps one verdict over the "
        f"input's range, a cell in stripes takes several; {conditional} of the {len(claims)} "
        f"claims have such a cell."
    )
    return path, alt
