"""The dashboard renderer (bridge/sorting_line_gym/envs/render.py): headless, deterministic, no ROS.

Part of the unit tier (no ROS, no network namespace, any user):
    .venv/bin/python -m pytest tests/python/unit/test_render.py -q
"""

from __future__ import annotations

import math
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from sorting_line_gym.envs import render
from support.dashboard_frames import make_frame

DashboardFrame = render.DashboardFrame
LiveDashboard = render.LiveDashboard
count_speed_changes = render.count_speed_changes
render_dashboard = render.render_dashboard
save_dashboard = render.save_dashboard


FRAMES = {
    "basic-reset": lambda: make_frame("basic", 0),
    "basic-1": lambda: make_frame("basic", 1, seed=1),
    "basic-37": lambda: make_frame("basic", 37, seed=2),
    "advanced-reset": lambda: make_frame("advanced", 0),
    "advanced-50": lambda: make_frame("advanced", 50, seed=3),
}


@pytest.mark.parametrize("name", sorted(FRAMES))
def test_render_shape_content_and_determinism(name):
    frame = FRAMES[name]()
    image = render_dashboard(frame)
    assert image.shape == (800, 1600, 3)
    assert image.dtype == np.uint8
    assert image.flags["C_CONTIGUOUS"]
    # Not blank: plenty of distinct colours and a real spread of values.
    assert image.std() > 20
    assert len(np.unique(image.reshape(-1, 3), axis=0)) > 200
    # The blue of material A and the orange of material B are both on it.
    assert np.any(np.all(image == (0x1F, 0x77, 0xB4), axis=-1))
    assert np.any(np.all(image == (0xFF, 0x7F, 0x0E), axis=-1))
    assert np.array_equal(image, render_dashboard(frame)), "same frame, different pixels"


def test_render_depends_on_the_frame():
    a = render_dashboard(make_frame("advanced", 20, seed=4))
    b = render_dashboard(make_frame("advanced", 21, seed=4))
    assert not np.array_equal(a, b)


@pytest.mark.parametrize("size", [(800, 400), (1234, 567), (2000, 800)])
def test_render_other_sizes(size):
    w, h = size
    image = render_dashboard(make_frame("basic", 10), width_px=w, height_px=h)
    assert image.shape == (h, w, 3)
    assert image.dtype == np.uint8


@pytest.mark.parametrize("variant", ["basic", "advanced"])
def test_save_png_and_svg(tmp_path, variant):
    frame = make_frame(variant, 25, seed=5)
    png, svg = tmp_path / "dash.png", tmp_path / "dash.SVG"
    save_dashboard(frame, png)
    save_dashboard(frame, str(svg))  # str or PathLike; suffix case does not matter
    assert png.stat().st_size > 10_000
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert svg.stat().st_size > 10_000
    text = svg.read_text()
    assert "<svg" in text and "</svg>" in text
    again = tmp_path / "again.svg"
    save_dashboard(frame, again)
    assert again.read_bytes() == svg.read_bytes(), "SVG output is not reproducible"


def test_png_matches_render(tmp_path):
    """The saved PNG is the rendered array."""
    from matplotlib.image import imread

    frame = make_frame("advanced", 12, seed=6)
    path = tmp_path / "d.png"
    save_dashboard(frame, path)
    png = (imread(path)[..., :3] * 255).round().astype(np.uint8)
    assert np.array_equal(png, render_dashboard(frame))


def test_edge_values_do_not_break_rendering():
    frame = make_frame(
        "advanced",
        3,
        seed=7,
        input_ab=(95, 0),
        belt_ab=(0, 0),
        machine_ab=(0, 0),
        containers=(0, 7, 123_456, 0),
        purity=123_456 / 123_463,
        belt_accuracy=math.nan,
        mode=None,
        history_mode=None,
        history_reward=[-0.5, math.nan, 1.0],
        title="a $title$ with 100% odd characters_{}",
        max_steps=1000,
    )
    assert render_dashboard(frame).shape == (800, 1600, 3)
    empty_input = make_frame("basic", 0, input_ab=(0, 0))
    assert render_dashboard(empty_input).shape == (800, 1600, 3)


def test_bad_arguments():
    with pytest.raises(ValueError, match="variant"):
        frame = make_frame("basic", 2)
        frame.variant = "fancy"
        render_dashboard(frame)
    with pytest.raises(ValueError, match="unsupported file type"):
        save_dashboard(make_frame("basic", 2), "/tmp/dashboard.jpg")


def test_speed_changes_count_from_the_start_speed():
    assert count_speed_changes([]) == 0
    assert count_speed_changes([0.6, 0.6]) == 0  # 0.6 is the start speed
    assert count_speed_changes([0.5]) == 1
    assert count_speed_changes([0.6, 0.8, 0.8, 0.30000000000000004, 0.3]) == 2


def test_modes_are_named():
    assert render.MODE_NAMES == {0: "basic", 1: "positive (A-rich)", 2: "negative (B-rich)"}


def test_headless_without_pyplot_and_live_dashboard_degrades():
    """render_dashboard never loads pyplot; LiveDashboard without a display warns once, then idles."""
    script = textwrap.dedent(
        f"""
        import sys, warnings
        sys.path.insert(0, {str(Path(__file__).resolve().parents[1])!r})
        from sorting_line_gym.envs.render import LiveDashboard, render_dashboard
        from support.dashboard_frames import make_frame
        frame = make_frame("advanced", 5)
        render_dashboard(frame)
        assert "matplotlib.pyplot" not in sys.modules, "render_dashboard imported pyplot"
        live = LiveDashboard()
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            for _ in range(3):
                live.show(frame)
            live.close()
        ours = [w for w in caught if "live dashboard" in str(w.message)]
        assert len(ours) == 1, [str(w.message) for w in caught]
        print("ok")
        """
    )
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY", "MPLBACKEND")}
    done = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "ok"


def test_live_dashboard_updates_one_window():
    """The window path, driven through pyplot with the Agg backend standing in for a display."""
    script = textwrap.dedent(
        f"""
        import sys, warnings
        import numpy as np
        sys.path.insert(0, {str(Path(__file__).resolve().parents[1])!r})
        from sorting_line_gym.envs.render import LiveDashboard, render_dashboard
        from support.dashboard_frames import make_frame
        import matplotlib.pyplot as plt
        LiveDashboard._pyplot = lambda self: plt  # pretend the backend is interactive
        warnings.simplefilter("ignore")  # Agg says it cannot show a window
        live = LiveDashboard()
        frames = [make_frame("advanced", n, seed=n) for n in (0, 1, 2)]
        for frame in frames:
            live.show(frame)
            assert plt.get_fignums() == [live._fig.number], plt.get_fignums()
        assert np.array_equal(np.asarray(live._image.get_array()), render_dashboard(frames[-1]))
        plt.close(live._fig)  # the user closes the window: the next show opens a new one
        live.show(frames[0])
        assert len(plt.get_fignums()) == 1
        live.close()
        assert plt.get_fignums() == []
        print("ok")
        """
    )
    env = dict(os.environ, MPLBACKEND="agg")
    done = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "ok"


def test_live_dashboard_close_without_show():
    live = LiveDashboard()
    live.close()
    live.close()
