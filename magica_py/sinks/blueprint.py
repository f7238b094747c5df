"""The default blueprint stored in every recording: a 3D view that follows the characters and
one plot per quantity, each titled with its unit.

Layout: the 3D view of ``/world`` on the left (3/5 of the width); on the right, stacked:
stretch (%), penetration (mm, only when a cloth has colliders), particle speed (m/s), the
wind each cloth feels (m/s², only with wind), a tab
pair "phase wall time (ms)" / "steps per frame", and the event log. Plots of one series hide
their legend (the title names it); the phase plot's legend sits top right.

The 3D camera tracks ``world/focus`` (two invisible points spanning the box of every joint and
particle, per frame): the viewer keeps the eye's offset to that box, so a walking character
stays in the picture and zooming heads for it. The eye starts in front of the characters and
to their right (scene frame; X is mirrored for the viewer, see ``layout``), at a distance that
fits the box of the first frame. The ground is Rerun's own line grid (0.5 m spacing, faint).
"""
from __future__ import annotations

import numpy as np

from magica_py.sinks import layout as L

EYE_DIRECTION = np.array([0.55, 0.4, 1.0])     # scene frame: right, up, front of the characters
MIN_VIEW_SIZE = 1.2                            # m: the smallest box the camera frames


def eye_placement(box_min: np.ndarray, box_max: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(eye position, look target) in the display frame for a scene-frame box."""
    mirror = np.array(L.DISPLAY_MIRROR)
    center = (np.asarray(box_min, float) + np.asarray(box_max, float)) * 0.5
    size = max(float(np.max(np.asarray(box_max, float) - np.asarray(box_min, float))), MIN_VIEW_SIZE)
    direction = EYE_DIRECTION / np.sqrt(float(EYE_DIRECTION @ EYE_DIRECTION))
    eye = center + direction * (1.1 * size + 0.3)
    return eye * mirror, center * mirror


def default_blueprint(title: str = "scene", *, box=None, penetration: bool = True, phases=(),
                      hidden=(L.ROOT_LINKS,), follow: bool = False, wind: bool = False):
    """The blueprint: ``box`` = (min, max) of the characters at the first frame (scene frame),
    ``phases`` the phase names plotted, ``hidden`` entities hidden at start (still toggleable),
    ``follow``: the time cursor follows the newest frame (opens a file at its last frame),
    ``wind``: a plot of the wind each cloth feels (``wind_view``)."""
    import rerun.blueprint as rrb

    eye = None
    if box is not None:
        position, target = eye_placement(*box)
        eye = rrb.EyeControls3D(position=position.tolist(), look_target=target.tolist(), eye_up=[0.0, 1.0, 0.0],
                                tracking_entity=L.reader_path(L.FOCUS))
    overrides = {L.reader_path(path): rrb.EntityBehavior(visible=False) for path in hidden}
    overrides[L.reader_path(L.FOCUS)] = rrb.EntityBehavior(interactive=False)
    scene = rrb.Spatial3DView(origin=L.reader_path(L.WORLD), name=f"{title} (viewer X = scene -X: right is right)",
                              eye_controls=eye, overrides=overrides,
                              line_grid=rrb.LineGrid3D(visible=True, spacing=0.5, color=list(L.COLOR_GRID),
                                                       stroke_width=1.0))

    def plot(path, name, legend=False):
        return rrb.TimeSeriesView(origin=L.reader_path(path), name=name,
                                  plot_legend=rrb.PlotLegend(corner=rrb.Corner2D.RightTop, visible=legend))

    plots = [plot(L.METRIC_MAX_STRETCH, "max edge stretch (%)")]
    if penetration:
        plots.append(plot(L.METRIC_MAX_PENETRATION, "max collider penetration (mm)"))
    plots.append(plot(L.METRIC_MAX_SPEED, "max particle speed (m/s)"))
    if wind:
        from magica_py.sinks.wind_view import METRIC_WIND

        plots.append(plot(METRIC_WIND, "wind felt per cloth (m/s²)", legend=True))
    timing = rrb.TimeSeriesView(
        origin=L.reader_path(L.METRIC_PHASE_TIME), name="phase wall time (ms, first frame left out)",
        contents=[L.reader_path(f"{L.METRIC_PHASE_TIME}/{p}_ms") for p in phases] or "$origin/**",
        plot_legend=rrb.PlotLegend(corner=rrb.Corner2D.RightTop, visible=True))
    plots.append(rrb.Tabs(timing, plot(L.METRIC_STEPS, "simulation steps per frame (count)"), active_tab=0))
    plots.append(rrb.TextLogView(origin=L.reader_path(L.EVENTS), name="events"))
    shares = [2] * (len(plots) - 2) + [4, 1.2]     # room for the phase legend's four lines
    return rrb.Blueprint(
        rrb.Horizontal(scene, rrb.Vertical(*plots, row_shares=shares), column_shares=[3, 2]),
        *([rrb.TimePanel(play_state="following")] if follow else []),
        collapse_panels=True)
