"""The showcases in the real Rerun viewer (Xvfb + Mesa's software Vulkan): the character is in
the 3D view at a readable size and no warning badge is shown. Skips, with the reason, where
the Debian packages are missing (apt-get install xvfb mesa-vulkan-drivers libvulkan1)."""
from __future__ import annotations

import numpy as np
import pytest

from magica_py.sinks import screenshot as shot

# few frames: the end of the recording is what the screenshot shows. character_walk at 3.3 s
# has turned right and left the 4 m patch the old framing was fixed on.
FRAMES = {"tail_orbit": 60, "character_walk": 200, "vrm_godette_mocap": 120}


def fake_screen(badge=False, character=((200, 400), (400, 600))):
    """A 1000 x 1600 picture laid out like the viewer: top bar line, the view's title bar, a
    vertical separator at 60 %, the time panel line; a blue character block; maybe a badge."""
    image = np.full((1000, 1600, 3), 13, np.int32)
    line = (53, 52, 52)
    image[70:72] = line
    image[940:942] = line
    image[:, 960:962] = line
    (y0, y1), (x0, x1) = character
    image[y0:y1, x0:x1] = (70, 160, 240)
    if badge:
        image[85:110, 600:625] = (223, 119, 0)
    return image


def analyse_array(tmp_path, image):
    from PIL import Image

    path = tmp_path / "fake.png"
    Image.fromarray(image.astype(np.uint8)).save(path)
    return shot.analyse(path)


def test_the_checker_finds_the_view_the_character_and_a_warning_badge(tmp_path):
    good = analyse_array(tmp_path, fake_screen())
    assert good.ok and good.view == (0, 122, 958, 940)
    assert good.character_box == (400, 200, 600, 400) and good.share == pytest.approx(4e4 / (958 * 818))
    bad = analyse_array(tmp_path, fake_screen(badge=True))
    assert any("warning badge" in p for p in bad.problems)
    cut = analyse_array(tmp_path, fake_screen(character=((122, 400), (300, 600))))
    assert any("touches the 3D view's border" in p for p in cut.problems)
    tiny = analyse_array(tmp_path, fake_screen(character=((500, 505), (500, 505))))
    assert any("too few character pixels" in p for p in tiny.problems)


@pytest.mark.skipif(shot.missing_tools() is not None, reason=f"real viewer: {shot.missing_tools()}")
def test_the_showcases_look_right_in_the_real_viewer(tmp_path):
    results = {}
    with shot.VirtualDisplay() as display:
        for name, frames in FRAMES.items():
            rrd = shot.record(name, frames, tmp_path, shot.pathlib.Path("configs"))
            png = tmp_path / f"{name}.png"
            shot.take_screenshot(rrd, png, display)
            results[name] = shot.analyse(png)
    problems = {name: check.problems for name, check in results.items() if not check.ok}
    assert not problems, problems
    for name, check in results.items():
        assert check.badge_pixels == 0 and check.share >= shot.MIN_SHARE, (name, check)
