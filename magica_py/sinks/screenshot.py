"""Render showcase recordings in the real Rerun viewer and check the screenshots.

    python -m magica_py.sinks.screenshot [--scenes tail_orbit character_walk ...] [--out DIR]

For each scene: record ``configs/NAME.yaml`` (in this process, with the solver; the file
opens at its last frame), open it in the viewer bundled with rerun-sdk on a virtual X display
(``Xvfb`` + Mesa's software Vulkan: ``rerun --renderer vulkan --screenshot-to``), and check
the PNG:

* the 3D view is found (the panel left of the vertical separator, between the top bar and
  the time panel);
* the character's pixels (particles, cloth edges and triangles: the layout's blue, red and
  amber) lie inside it, clear of its borders (nothing cut off), and their bounding box covers
  a reasonable share of it (``MIN_SHARE``..``MAX_SHARE``);
* no warning badge (the viewer's orange "!" icon, e.g. for a left-handed frame) is shown in the
  view's title bar.

Needs the Debian packages ``xvfb mesa-vulkan-drivers libvulkan1`` (``missing_tools`` says
what is missing; the test skips with that reason). Timings on a software rasterizer: about
30 s per screenshot.
"""
from __future__ import annotations

import argparse
import dataclasses
import os
import pathlib
import shutil
import signal
import subprocess
import sys
import tempfile
import time

import numpy as np

# scene -> frames recorded (the screenshot shows the last one)
SHOWCASES = {"tail_orbit": 100, "character_walk": 360, "vrm_godette_mocap": 240}
WINDOW = "960x600"                 # logical points; the PNG is at the display's scale
MIN_SHARE, MAX_SHARE = 0.02, 0.85  # character bounding box / 3D view area
MIN_PIXELS = 0.0015                # character pixels / 3D view area
BORDER = 3                         # px: the character must stay this far from the view's edges
VULKAN_ICDS = ("/usr/share/vulkan/icd.d", "/etc/vulkan/icd.d")


def missing_tools() -> str | None:
    """Why the viewer cannot be run here under Xvfb (None: it can)."""
    from magica_py.sinks.live import viewer_executable

    missing = [name for name in ("Xvfb",) if shutil.which(name) is None]
    if not any(pathlib.Path(d).is_dir() and any(pathlib.Path(d).glob("lvp_icd*.json")) for d in VULKAN_ICDS):
        missing.append("Mesa's software Vulkan driver (lvp_icd)")
    if viewer_executable() is None:
        missing.append("the rerun viewer executable")
    if not missing:
        return None
    return ("needs " + ", ".join(missing) + " (Debian: apt-get install xvfb mesa-vulkan-drivers libvulkan1; "
            "the viewer comes with rerun-sdk)")


class VirtualDisplay:
    """An Xvfb server on a free display number, stopped (by its pid) on exit."""

    def __init__(self, size: str = "1920x1200x24"):
        self.size = size
        self.process = None
        self.display = None

    def __enter__(self) -> str:
        read, write = os.pipe()
        self.process = subprocess.Popen(["Xvfb", "-displayfd", str(write), "-screen", "0", self.size, "-nolisten",
                                         "tcp"], pass_fds=(write,), stdout=subprocess.DEVNULL,
                                        stderr=subprocess.DEVNULL)
        os.close(write)
        with os.fdopen(read) as pipe:
            number = pipe.readline().strip()
        if not number.isdigit():
            self.__exit__(None, None, None)
            raise RuntimeError("Xvfb did not report a display number")
        self.display = f":{number}"
        return self.display

    def __exit__(self, *exc) -> None:
        if self.process is not None and self.process.poll() is None:
            self.process.terminate()
            try:
                self.process.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()


def take_screenshot(rrd: pathlib.Path, png: pathlib.Path, display: str, window: str = WINDOW,
                    timeout: float = 240.0) -> float:
    """Open ``rrd`` in the viewer on ``display`` and save a screenshot; returns the seconds it took."""
    from magica_py.sinks.live import viewer_executable

    env = dict(os.environ, DISPLAY=display, RERUN_APP_ONLY="true")
    env.pop("WAYLAND_DISPLAY", None)
    start = time.perf_counter()
    # its own process group: the venv's `rerun` is a wrapper that starts the real viewer as a child,
    # and a timeout must stop both
    viewer = subprocess.Popen([viewer_executable(), "--renderer", "vulkan", "--port", "auto", "--window-size", window,
                               "--hide-welcome-screen", "--screenshot-to", str(png), str(rrd)],
                              env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, start_new_session=True)
    try:
        output, _ = viewer.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        os.killpg(viewer.pid, signal.SIGKILL)
        viewer.communicate()
        raise RuntimeError(f"the viewer did not save {png} within {timeout:.0f} s") from None
    if viewer.returncode != 0 or not png.exists():
        tail = output.decode(errors="replace")[-2000:]
        raise RuntimeError(f"the viewer did not save {png} (exit {viewer.returncode}):\n{tail}")
    return time.perf_counter() - start


@dataclasses.dataclass
class ShotCheck:
    """What a screenshot shows (pixel units of the PNG)."""

    path: str
    view: tuple[int, int, int, int]            # 3D view content: x0, y0, x1, y1 (exclusive)
    character_pixels: int
    character_box: tuple[int, int, int, int] | None
    share: float                               # character box area / view area
    badge_pixels: int                          # warning-badge orange in the view's title bar
    problems: list[str]

    @property
    def ok(self) -> bool:
        return not self.problems


def _line_colour(pixels: np.ndarray, tolerance: int = 6) -> np.ndarray | None:
    """The colour of a panel separator line, if ``pixels`` (k, 3) are one: uniform and lighter
    than the viewer's near-black background."""
    median = np.median(pixels, axis=0)
    if np.all(np.abs(pixels - median).sum(axis=1) <= tolerance) and 100 < float(median.sum()) < 400:
        return median
    return None


def find_3d_view(image: np.ndarray) -> tuple[int, int, int, int, int]:
    """(x0, y0, x1, y1, title_top) of the left panel's content (the 3D view of the blueprint):
    right of it the vertical separator, above it the top bar's separator line and the view's
    title bar, below it the time panel's separator line."""
    h, w, _ = image.shape
    rows = np.arange(int(0.3 * h), int(0.7 * h))
    separator, colour = None, None
    for x in range(int(0.35 * w), int(0.85 * w)):
        colour = _line_colour(image[rows, x])
        if colour is not None:
            separator = x
            break
    if separator is None:
        raise ValueError("no vertical panel separator found: is this the magica_py blueprint?")
    left = image[:, : separator - 2: 4]
    lines = [y for y in range(h) if np.all(np.abs(left[y] - colour).sum(axis=1) <= 6)]
    top = [y for y in lines if y < 0.2 * h]
    bottom = [y for y in lines if y > 0.8 * h]
    title_top = max(top) + 1 if top else 0
    # the view's title bar: 28 points below the top bar's line (about 5 % of the height)
    y0 = title_top + int(round(0.05 * h))
    y1 = min(bottom) if bottom else h
    return 0, y0, separator - 2, y1, title_top


def character_mask(rgb: np.ndarray) -> np.ndarray:
    """Pixels of the layout's particle blue / fixed red / edge amber (shaded), not the grid's greys."""
    r, g, b = (rgb[..., i].astype(np.int32) for i in range(3))
    blue = (b > 150) & (b > r + 60) & (b > g + 15)
    red = (r > 150) & (r > g + 70) & (r > b + 70) & (g < 130)
    amber = (r > 200) & (g > 150) & (b < 120) & (r > b + 100)
    return blue | red | amber


def analyse(png: pathlib.Path) -> ShotCheck:
    from PIL import Image

    image = np.asarray(Image.open(png).convert("RGB")).astype(np.int32)
    x0, y0, x1, y1, title_top = find_3d_view(image)
    view = image[y0:y1, x0:x1]
    mask = character_mask(view)
    area = max((x1 - x0) * (y1 - y0), 1)
    count = int(mask.sum())
    problems = []
    box = None
    share = 0.0
    if count:
        ys, xs = np.nonzero(mask)
        box = (int(xs.min()) + x0, int(ys.min()) + y0, int(xs.max()) + x0 + 1, int(ys.max()) + y0 + 1)
        share = (box[2] - box[0]) * (box[3] - box[1]) / area
        if xs.min() < BORDER or ys.min() < BORDER or xs.max() >= x1 - x0 - BORDER or ys.max() >= y1 - y0 - BORDER:
            problems.append(f"the character touches the 3D view's border (box {box}, view {(x0, y0, x1, y1)})")
    if count < MIN_PIXELS * area:
        problems.append(f"too few character pixels in the 3D view: {count} ({100 * count / area:.2f} %)")
    if count and not MIN_SHARE <= share <= MAX_SHARE:
        problems.append(f"the character's box covers {100 * share:.1f} % of the 3D view "
                        f"(expected {100 * MIN_SHARE:.0f}-{100 * MAX_SHARE:.0f} %)")
    title = image[title_top:y0, x0:x1]
    r, g, b = title[..., 0], title[..., 1], title[..., 2]
    badge = int(((r > 190) & (g > 80) & (g < 160) & (b < 60)).sum())
    if badge > 20:
        problems.append(f"a warning badge is shown in the 3D view's title bar ({badge} orange pixels)")
    return ShotCheck(str(png), (x0, y0, x1, y1), count, box, share, badge, problems)


def record(name: str, frames: int, out: pathlib.Path, configs: pathlib.Path) -> pathlib.Path:
    from magica_py.config import load_scene
    from magica_py.sinks.record_all import record_scene

    path = out / f"{name}.rrd"
    record_scene(load_scene(configs / f"{name}.yaml"), path, frames=frames, open_at_end=True)
    return path


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m magica_py.sinks.screenshot", description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", nargs="+", default=list(SHOWCASES), help="config stems (default: %(default)s)")
    parser.add_argument("--frames", type=int, help="frames to record (default: per scene, see SHOWCASES)")
    parser.add_argument("--configs", default="configs", type=pathlib.Path)
    parser.add_argument("--out", type=pathlib.Path, help="folder for the .rrd and .png files (default: a temporary one)")
    parser.add_argument("--window", default=WINDOW, help="viewer window size in points (default %(default)s)")
    args = parser.parse_args(argv)
    reason = missing_tools()
    if reason:
        print(f"screenshot: cannot run the viewer here: {reason}", file=sys.stderr)
        return 2
    out = args.out or pathlib.Path(tempfile.mkdtemp(prefix="magica_shots_"))
    out.mkdir(parents=True, exist_ok=True)
    failures = 0
    with VirtualDisplay() as display:
        for name in args.scenes:
            rrd = record(name, args.frames or SHOWCASES.get(name, 120), out, args.configs)
            png = out / f"{name}.png"
            seconds = take_screenshot(rrd, png, display, args.window)
            check = analyse(png)
            failures += not check.ok
            print(f"{name:<20} {'ok  ' if check.ok else 'FAIL'} character box {100 * check.share:5.1f} % of the "
                  f"3D view, {check.character_pixels} px, badge px {check.badge_pixels}, view {check.view}, "
                  f"screenshot {seconds:.0f} s -> {png}", flush=True)
            for problem in check.problems:
                print(f"    {problem}")
    return 1 if failures else 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
