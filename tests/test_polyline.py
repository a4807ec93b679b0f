"""Polylines resampled by arc length (:func:`kinlearn.polyline.resample`)."""

from __future__ import annotations

import numpy as np

from kinlearn.polyline import resample


def test_resampling_is_even_in_arc_length():
    vertices = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]])
    expected = np.array([[0, 0], [0.5, 0], [1, 0], [1, 0.5], [1, 1.0]])
    np.testing.assert_allclose(resample(vertices, 5), expected, atol=1e-15)
    # 4 points on a path of length 2: spacing 2/3 along the path, the corner is cut.
    np.testing.assert_allclose(resample(vertices, 4)[1:3], [[2 / 3, 0], [1, 1 / 3]], atol=1e-15)
    np.testing.assert_array_equal(resample(np.ones((3, 2)), 4), np.ones((4, 2)))  # zero length


def test_resampling_keeps_the_ends_and_the_corners_it_lands_on():
    poly = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 3.0]])
    assert np.allclose(resample(poly, 5), [[0, 0], [1, 0], [1, 1], [1, 2], [1, 3]])
    path = np.random.default_rng(0).normal(size=(7, 6))
    out = resample(path, 12)
    assert out.shape == (12, 6)
    np.testing.assert_array_equal(out[[0, -1]], path[[0, -1]])
