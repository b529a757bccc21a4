"""Hand-eye from pose lists: accuracy of OpenCV's closed forms and of the ML refinement against
the Cramer-Rao bound, and time per call.

Standard scenario: :func:`calstudy.handeye.simulate.simulate_cell` with 15 poses,
camera-pose noise 1e-3 rad and 0.2 mm, 200 trials (each its own cell). Goals: ML RMS
error within 10 % of the bound, ML median error at least 2x below the best closed form, one
refinement on 100 poses within 50 ms; the whole calibration (closed forms on 12 well-spread
poses, refinement, fit check) linear in the pose count: 100 poses within 20 ms, 1,000 within
200 ms; the diagnosis of a failed check within 1 s; the import of the tool within 1 s.
"""

from __future__ import annotations

import subprocess
import sys
import time

import numpy as np
from timing import best_ms

from calstudy import CalibrationError
from calstudy import handeye as he
from calstudy.core import geometry as geo
from calstudy.handeye import calibrate as hp
from calstudy.handeye import inputs as hi
from calstudy.handeye import refine as hr
from calstudy.handeye import simulate as hs

N_POSES, SIGMA_ROT, SIGMA_TRANS, TRIALS = 15, 1e-3, 0.2, 200
METHODS = list(he.OPENCV_METHODS) + list(hr.OPENCV_RWHE_METHODS)
BUDGET_MS = 50.0
REPEATS = 10
#: pose counts of the whole calibration's timing, and the budgets (ms) of some
POSE_COUNTS = (10, 100, 300, 1000)
CALIBRATE_BUDGET_MS = {100: 20.0, 1000: 200.0}
DIAGNOSIS_BUDGET_S = IMPORT_BUDGET_S = 1.0


def trial(seed: int) -> tuple[dict, np.ndarray]:
    """Errors ``{method: (rot rad, trans mm)}`` of one cell, and its CRB of ``X``."""
    cell = hs.simulate_cell(np.random.default_rng(seed), N_POSES, SIGMA_ROT, SIGMA_TRANS)
    prep = hi.prepare_poses(cell.flange2base, cell.target2camera)
    forms = hr.closed_forms(prep.a, prep.b, METHODS)
    out = {}
    for c in forms:
        if c.x is not None:
            out[c.method] = (
                geo.rotation_error(c.x, cell.camera2flange),
                geo.translation_error(c.x, cell.camera2flange),
            )
    start = min((c for c in forms if not c.refused), key=lambda c: c.score)
    est = hr.refine_ml(prep.a, prep.b, start.x, start.z, SIGMA_ROT, SIGMA_TRANS)
    x = est.value[0]
    out["ML"] = (
        geo.rotation_error(x, cell.camera2flange),
        geo.translation_error(x, cell.camera2flange),
    )
    truth = hi.prepare_poses(cell.flange2base, cell.target2camera_true)
    crb = hr.handeye_crb(
        truth.a, truth.b, cell.camera2flange, cell.target2base, SIGMA_ROT, SIGMA_TRANS
    )
    return out, crb


def main() -> None:
    errors: dict[str, list] = {}
    crb_rot, crb_trans = [], []
    for seed in range(TRIALS):
        out, crb = trial(seed)
        for k, v in out.items():
            errors.setdefault(k, []).append(v)
        crb_rot.append(np.trace(crb[:3, :3]))
        crb_trans.append(np.trace(crb[3:6, 3:6]))
    bound = np.rad2deg(np.sqrt(np.mean(crb_rot))), np.sqrt(np.mean(crb_trans))
    print(
        f"hand-eye, {N_POSES} poses, sigma {SIGMA_ROT:g} rad / {SIGMA_TRANS:g} mm, {TRIALS} "
        "trials: error of camera2flange"
    )
    print(f"  {'method':<12s} {'median rot':>11s} {'median t':>9s} {'RMS rot':>9s} {'RMS t':>8s}")
    medians = {}
    for name, errs in errors.items():
        e = np.array(errs)
        med = np.rad2deg(np.median(e[:, 0])), np.median(e[:, 1])
        rms = np.rad2deg(np.sqrt(np.mean(e[:, 0] ** 2))), np.sqrt(np.mean(e[:, 1] ** 2))
        medians[name] = (med, rms)
        print(
            f"  {name:<12s} {med[0]:9.4f} deg {med[1]:6.3f} mm {rms[0]:7.4f} deg {rms[1]:5.3f} mm"
            + (f"   ({len(errs)} of {TRIALS} finite)" if len(errs) < TRIALS else "")
        )
    print(f"  {'CRB (RMS)':<12s} {'':>13s} {'':>9s} {bound[0]:7.4f} deg {bound[1]:5.3f} mm")
    (ml_med, ml_rms) = medians.pop("ML")
    ratio = ml_rms[0] / bound[0], ml_rms[1] / bound[1]
    print(
        f"  ML RMS / CRB: rotation {ratio[0]:.3f}, translation {ratio[1]:.3f}   (goal: within 10 %)"
    )
    best_rot = min(medians, key=lambda k: medians[k][0][0])
    best_t = min(medians, key=lambda k: medians[k][0][1])
    print(
        f"  best closed form / ML, median: rotation {medians[best_rot][0][0] / ml_med[0]:.2f} "
        f"({best_rot}), translation {medians[best_t][0][1] / ml_med[1]:.2f} ({best_t})   "
        "(goal: >= 2)"
    )
    cell = hs.simulate_cell(np.random.default_rng(0), 100, SIGMA_ROT, SIGMA_TRANS)
    prep = hi.prepare_poses(cell.flange2base, cell.target2camera)
    forms = {c.method: c for c in hr.closed_forms(prep.a, prep.b, METHODS)}
    x0, z0 = forms["Park"].x, forms["Park"].z
    small = hs.simulate_cell(np.random.default_rng(1), N_POSES, SIGMA_ROT, SIGMA_TRANS)
    sp = hi.prepare_poses(small.flange2base, small.target2camera)
    print(f"time per call, best of {REPEATS}:")
    for name in METHODS:
        ms = best_ms(lambda name=name: hr.closed_forms(sp.a, sp.b, [name]), REPEATS)
        print(f"  {name:<40s} {ms:8.2f} ms   ({N_POSES} poses)")
    ms = best_ms(lambda: hr.refine_ml(prep.a, prep.b, x0, z0, SIGMA_ROT, SIGMA_TRANS), REPEATS)
    print(
        f"  {'ML refinement (refine_ml)':<40s} {ms:8.2f} ms   (100 poses; budget {BUDGET_MS:g} ms)"
    )
    for n in POSE_COUNTS:
        big = hs.simulate_cell(np.random.default_rng(n), n, SIGMA_ROT, SIGMA_TRANS)
        ms = best_ms(lambda big=big: hp.calibrate_handeye(big.flange2base, big.target2camera), 5)
        budget = CALIBRATE_BUDGET_MS.get(n)
        print(
            f"  {'calibrate_handeye (5 starts, ML, check)':<40s} {ms:8.2f} ms   ({n} poses"
            + (f"; budget {budget:g} ms)" if budget else ")")
        )
    shuffled = cell.target2camera[np.random.default_rng(0).permutation(len(cell.target2camera))]
    ms = best_ms(lambda: _refused(cell.flange2base, shuffled), 3)
    print(
        f"  {'refusal with diagnosis (rows shuffled)':<40s} {ms:8.2f} ms   (100 poses; budget "
        f"{1000 * DIAGNOSIS_BUDGET_S:g} ms)"
    )
    print(
        f"  {'import of calstudy.handeye':<40s} {1000 * import_seconds():8.1f} ms"
        f"   (a fresh interpreter, its start-up subtracted; budget {1000 * IMPORT_BUDGET_S:g} ms)"
    )


def _refused(a, b) -> None:
    try:
        hp.calibrate_handeye(a, b)
    except CalibrationError:
        return
    raise AssertionError("the shuffled pose list was not refused")


def import_seconds(repeats: int = 5) -> float:
    """Best wall time of importing the tool in a fresh interpreter, less the interpreter's own
    start-up (best of ``repeats`` each)."""

    def best(code: str) -> float:
        out = float("inf")
        for _ in range(repeats):
            start = time.perf_counter()
            subprocess.run([sys.executable, "-c", code], check=True)
            out = min(out, time.perf_counter() - start)
        return out

    return best("import calstudy.handeye") - best("pass")


if __name__ == "__main__":
    main()
