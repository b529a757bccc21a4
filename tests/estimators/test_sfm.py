"""Tests of calstudy.estimators.sfm and calstudy.estimators.stereo_views: the image graph and
clusters of Eq. 5-6, triangulation with the shared stereo rig (the dualarm paper's tests of the
reconstruction and of calstudy.estimators.bundle are in tests/papers/dualarm)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from calstudy.core.errors import CalibrationError
from calstudy.estimators import sfm, stereo_views
from calstudy.models.sensors import PinholeCamera
from calstudy.models.stereo import stereo_rig

CAMERA = PinholeCamera(fx=2000.0, fy=1990.0, cx=640.0, cy=512.0, width=1280, height=1024)


def test_triangulation_of_an_ideal_rig_is_exact():
    rig = stereo_rig(CAMERA, 200.0, 1000.0)
    p = np.array([[10.0, -20.0, 950.0], [-40.0, 30.0, 1100.0]])
    np.testing.assert_allclose(rig.triangulate(*rig.project(p)), p, atol=1e-6)


def test_a_rig_with_lens_distortion_is_refused():
    distorted = dataclasses.replace(CAMERA, dist=(-0.1, 0.0, 0.0, 0.0))
    rig = stereo_rig(distorted, 200.0, 1000.0)
    uv = np.array([[640.0, 512.0], [700.0, 500.0], [600.0, 540.0], [650.0, 600.0]])
    view = stereo_views.make_view([0, 1, 2, 3], uv, uv + [-50.0, 0.0])
    with pytest.raises(CalibrationError, match="lens distortion"):
        sfm.reconstruct_cluster(rig, [view], 0, [0])
    with pytest.raises(CalibrationError, match="lens distortion"):
        sfm.pnp_pose(np.random.default_rng(0).normal(0, 50, (4, 3)) + [0, 0, 900], uv, distorted)


def test_image_graph_and_clusters():
    views = [
        stereo_views.make_view([0, 1, 2, 3, 4], np.zeros((5, 2)), np.zeros((5, 2))),
        stereo_views.make_view([2, 3, 4, 5, 6], np.zeros((5, 2)), np.zeros((5, 2))),
        stereo_views.make_view([3, 4, 5, 6, 7, 8], np.zeros((6, 2)), np.zeros((6, 2))),
        stereo_views.make_view([9, 10, 11, 12], np.zeros((4, 2)), np.zeros((4, 2))),
    ]
    w = sfm.image_graph(views)
    assert w.tolist() == [[0, 3, 2, 0], [3, 0, 4, 0], [2, 4, 0, 0], [0, 0, 0, 0]]
    clusters = sfm.cluster_images(w, alpha=3)
    # view 1 covers 0, 1, 2; view 3 stands alone
    assert clusters == [(1, [0, 1, 2]), (3, [3])]
