"""Time the bundle adjustment of the full coded-marker set (budget 2 s).

Builds one survey of the 14 markers of Table A1 with the default noise (24 stereo images), splices
the clusters and prints the best of several repeats (wall clock) of
``calstudy.estimators.sfm.bundle_adjust`` from that start, with the analytic sparse Jacobian (what
the
notebook uses) and with finite differences on ``jac_sparsity``, and of the whole reconstruction
(graph, clusters, PnP, splice and bundle adjustment).
"""

from __future__ import annotations

import numpy as np
from timing import best_seconds

from calstudy.estimators import sfm as mk
from calstudy.papers.dualarm import experiments as ex
from calstudy.papers.dualarm import simulate as sim
from calstudy.papers.dualarm.scenario import load_scenario

BUDGET_S = 2.0
REPEATS = 5


def main() -> None:
    scn = load_scenario()
    views = sim.survey_views(scn, np.random.default_rng(1))
    recon = ex.survey_markers(scn, views)
    used = [views[j] for j in recon.used_views]
    w2c, pts = mk.splice_clusters(recon.clusters)
    poses = np.stack([w2c[j] for j in range(len(used))])
    points = np.full((len(scn.markers), 3), np.nan)
    for i, p in pts.items():
        points[i] = p
    kw = dict(
        fixed_view=recon.reference_view,
        sigma_px=scn.sigma_px,
        sigma_mm=scn.marker_sigma_mm,
        depth_ref_mm=scn.working_distance_mm,
    )
    n_obs = sum(v.ids.size for v in used)
    timings = {
        "bundle adjustment, analytic sparse Jacobian": best_seconds(
            lambda: mk.bundle_adjust(scn.rig, used, poses, points, **kw), REPEATS
        ),
        "bundle adjustment, finite differences on jac_sparsity": best_seconds(
            lambda: mk.bundle_adjust(scn.rig, used, poses, points, jacobian="sparse-fd", **kw),
            REPEATS,
        ),
        "whole reconstruction (graph to bundle adjustment)": best_seconds(
            lambda: ex.survey_markers(scn, views), REPEATS
        ),
    }
    print(
        f"dualarm: {len(scn.markers)} markers, {len(used)} stereo images, {n_obs} observations, "
        f"{len(recon.clusters)} cluster(s), best of {REPEATS}"
    )
    for label, s in timings.items():
        print(f"  {label:<55s} {s:8.3f} s   (budget {BUDGET_S:g} s)")


if __name__ == "__main__":
    main()
