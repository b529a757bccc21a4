"""Speed of notebook 04: full-frame circle-of-confusion rectification (budget 1 s) and one trial.

Times ``calstudy.estimators.coc.rectify_coc`` (vectorised, float32, OpenCV filters, strips on
all cores) on a synthetic full frame of blurred dots, best of several repeats, and the per-pixel
loop of the paper's flowchart (``rectify_coc_reference``) on a crop, scaled to the full frame.
The circle-of-confusion radius is that of Eq. 4 for a dot at 900 mm with the optics of
``data/binocular/sensor.toml``. Then one Monte Carlo trial of the notebook
(``experiments.binocular_trial``, default sweeps; budget: 200 trials plus 30 field trials in 2
minutes on 2 workers, about 1.1 s per trial).
"""

from __future__ import annotations

import json

import cv2
import numpy as np
from timing import best_seconds

from calstudy.core.paths import RESULTS_DIR
from calstudy.estimators import coc
from calstudy.papers.binocular import experiments
from calstudy.papers.binocular.scenario import load_scenario

BUDGET_S = 1.0
TRIAL_BUDGET_S = 1.1
REPEATS = 5
CROP = 40


def frame(width: int, height: int, delta: float) -> np.ndarray:
    """A float32 frame: 6 % background and a grid of bright dots, blurred by the CoC."""
    img = np.full((height, width), 15, np.uint8)
    for v in range(300, height - 300, 600):
        for u in range(300, width - 300, 600):
            cv2.circle(img, (u, v), 35, 230, -1, lineType=cv2.LINE_AA)
    out = img.astype(np.float32)
    out /= 255.0
    return cv2.GaussianBlur(out, (0, 0), delta)


def main() -> None:
    scenario = load_scenario()
    delta = float(scenario.coc_radius_px(900.0))
    width, height = scenario.rig.left.width, scenario.rig.left.height
    img = frame(width, height, delta)
    full = best_seconds(lambda: coc.rectify_coc(img, delta), REPEATS)
    crop = img[300 - CROP // 2 : 300 + CROP // 2, 265 - CROP // 2 : 265 + CROP // 2].copy()
    loop = best_seconds(lambda: coc.rectify_coc_reference(crop, delta), 1)
    scaled = loop / crop.size * img.size
    verdict = "within" if full <= BUDGET_S else "OVER"
    print(
        f"frame {width} x {height} px ({img.size / 1e6:.1f} Mpx), float32, "
        f"CoC radius {delta:.2f} px"
    )
    print(
        f"vectorised rectification: {full:.2f} s (best of {REPEATS}); "
        f"budget {BUDGET_S:.1f} s: {verdict}"
    )
    print(
        f"per-pixel flowchart loop: {loop:.2f} s on a {CROP} x {CROP} crop -> "
        f"{scaled / 3600:.1f} h scaled to the frame; vectorised is {scaled / full:,.0f} x faster"
    )
    f_number = calibrated_f_number()
    setup = experiments.binocular_experiment(n_trials=1, f_number=f_number).scenario
    rng = iter(range(100))
    one = best_seconds(
        lambda: experiments.binocular_trial(setup, np.random.default_rng(next(rng))), REPEATS
    )
    verdict = "within" if one <= TRIAL_BUDGET_S else "OVER"
    print(
        f"one trial at f/{setup.scenario.sensor.optics.f_number:.3g} (Tables 2-4, "
        f"Fig. 13, both sweeps, oracles): {one:.2f} s (best of {REPEATS}); budget "
        f"{TRIAL_BUDGET_S:.1f} s: {verdict}"
    )
    sweep = experiments.optics_experiment("bench", n_trials=1, points=[{}], f_number=f_number)
    table2 = best_seconds(
        lambda: experiments.optics_trial(sweep.scenario, np.random.default_rng(next(rng))),
        REPEATS,
    )
    print(f"one optics-sweep trial (Table 2 only, oracle): {table2:.2f} s (best of {REPEATS})")


def calibrated_f_number() -> float | None:
    """The F-number notebook 04 calibrated (its ``run.json``), None if it has not run."""
    path = RESULTS_DIR / "04_binocular_correction" / "run.json"
    if not path.is_file():
        return None
    return json.loads(path.read_text()).get("parameters", {}).get("f_number")


if __name__ == "__main__":
    main()
