"""Plots (nurbscnc.output.plots; issue 5): each writes a real, non-blank PNG of the expected size.

The images are read back with matplotlib.image.imread (the oracle for "is a PNG of this size");
the path plot is also checked for its highlight colour, present exactly when corner pieces are.
"""

from __future__ import annotations

import sys

import numpy as np
import pytest

from nurbscnc.errors import ConfigError, OutputError
from nurbscnc.output import plots

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
WIDTH_PX = round(plots.FIGSIZE_IN[0] * plots.DPI)
HEIGHT_PX = round(plots.FIGSIZE_IN[1] * plots.DPI)


@pytest.fixture(scope="module")
def mpl_image():
    image = pytest.importorskip(
        "matplotlib.image", reason="matplotlib (the 'plot' extra) is not installed"
    )
    return image


def _read_png(path, mpl_image) -> np.ndarray:
    with open(path, "rb") as fh:
        assert fh.read(8) == PNG_SIGNATURE
    img = mpl_image.imread(path)
    assert img.shape[:2] == (HEIGHT_PX, WIDTH_PX)
    assert float(np.var(img[..., :3])) > 0.0  # not blank
    return img


def _has_colour(img: np.ndarray, rgb, tol: float = 0.02) -> bool:
    return bool(np.any(np.all(np.abs(img[..., :3] - np.asarray(rgb)) < tol, axis=-1)))


def _square_with_corners():
    side = np.linspace(0.0, 10.0, 50)
    path = np.concatenate(
        [
            np.column_stack([side, 0 * side]),
            np.column_stack([10 + 0 * side, side]),
            np.column_stack([side[::-1], 10 + 0 * side]),
        ]
    )
    s = np.linspace(0.0, np.pi / 2, 30)
    corner = np.column_stack([9 + np.sin(s), 1 - np.cos(s), 0 * s])  # rounds (10, 0)
    return np.column_stack([path, np.zeros(len(path))]), [corner]


def test_plot_path_marks_corner_pieces(tmp_path, mpl_image):
    path, pieces = _square_with_corners()
    red = (214 / 255, 39 / 255, 40 / 255)  # matplotlib's "tab:red"
    with_pieces = plots.plot_path(path, pieces, str(tmp_path / "path.png"))
    assert with_pieces == str(tmp_path / "path.png")
    assert _has_colour(_read_png(with_pieces, mpl_image), red)
    without = plots.plot_path(path[:, :2], [], str(tmp_path / "bare.png"))
    assert not _has_colour(_read_png(without, mpl_image), red)


def test_plot_feed_profiles(tmp_path, mpl_image):
    t = np.linspace(0.0, 2.0, 2001)
    profiles = {
        "adaptive": (t, 58.3 * np.ones_like(t)),
        "curvature": (t, 58.3 / (1 + 5 * np.exp(-((t - 1) ** 2) / 0.01))),
        "ph-lookahead": (t, 58.3 * np.minimum(1.0, 5 * t)),
    }
    _read_png(plots.plot_feed_profiles(profiles, str(tmp_path / "feed.png")), mpl_image)


def test_plot_contour_error_large_series(tmp_path, mpl_image):
    t = np.arange(200_000) * 1e-3
    errs = {"ph-lookahead": (t, 10 * np.sin(t)), "adaptive": (t, 40 * np.sin(3 * t))}
    _read_png(plots.plot_contour_error(errs, str(tmp_path / "contour.png")), mpl_image)


def test_plot_axis_errors(tmp_path, mpl_image):
    t = np.linspace(0.0, 1.0, 1001)
    errs = {"a": (t, 18.7 * np.cos(6 * t), 18.7 * np.sin(6 * t)), "b": (t, 0 * t, t)}
    _read_png(plots.plot_axis_errors(errs, str(tmp_path / "axes.png")), mpl_image)


def test_bad_inputs_and_unwritable_folder(tmp_path, mpl_image):
    t = np.arange(5.0)
    with pytest.raises(ConfigError, match="nothing to plot"):
        plots.plot_feed_profiles({}, str(tmp_path / "x.png"))
    with pytest.raises(ConfigError, match="equally long"):
        plots.plot_contour_error({"a": (t, t[:3])}, str(tmp_path / "x.png"))
    with pytest.raises(ConfigError, match="3 equally long"):
        plots.plot_axis_errors({"a": (t, t)}, str(tmp_path / "x.png"))
    with pytest.raises(ConfigError, match="path_mm"):
        plots.plot_path(np.zeros(4), [], str(tmp_path / "x.png"))
    with pytest.raises(OutputError):
        plots.plot_feed_profiles({"a": (t, t)}, str(tmp_path / "missing" / "x.png"))
    assert list(tmp_path.iterdir()) == []  # nothing half-written


def test_missing_matplotlib_says_how_to_install(tmp_path, monkeypatch):
    # A None entry in sys.modules makes the import raise ImportError, as if not installed.
    monkeypatch.setitem(sys.modules, "matplotlib.figure", None)
    monkeypatch.setitem(sys.modules, "matplotlib.backends.backend_agg", None)
    with pytest.raises(ConfigError, match=r"pip install 'nurbscnc\[plot\]'"):
        plots.plot_feed_profiles({"a": (np.arange(3.0), np.arange(3.0))}, str(tmp_path / "x.png"))
    assert not (tmp_path / "x.png").exists()
