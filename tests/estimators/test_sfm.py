"""Coded markers: the image graph and the clustering of Eq. 5-6 (dualarm)."""

from __future__ import annotations

import numpy as np

from calstudy.estimators import sfm as mk


def test_image_graph_and_clusters():
    views = [
        mk.make_view([0, 1, 2, 3, 4], np.zeros((5, 2)), np.zeros((5, 2))),
        mk.make_view([2, 3, 4, 5, 6], np.zeros((5, 2)), np.zeros((5, 2))),
        mk.make_view([3, 4, 5, 6, 7, 8], np.zeros((6, 2)), np.zeros((6, 2))),
        mk.make_view([9, 10, 11, 12], np.zeros((4, 2)), np.zeros((4, 2))),
    ]
    w = mk.image_graph(views)
    assert w.tolist() == [[0, 3, 2, 0], [3, 0, 4, 0], [2, 4, 0, 0], [0, 0, 0, 0]]
    clusters = mk.cluster_images(w, alpha=3)
    # view 1 covers 0, 1, 2; view 3 stands alone
    assert clusters == [(1, [0, 1, 2]), (3, [3])]
