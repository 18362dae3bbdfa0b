"""The layout a recording opens with: the 3D scene beside time series of errors, contacts and phases."""

from __future__ import annotations

import rerun.blueprint as rrb

# metric entity groups (see wristmimic.view.record for what each holds)
POSITION_ERRORS = ["/metrics/error/object_pos/**", "/metrics/error/wrist_pos/**", "/metrics/error/body_pos/**"]
ROTATION_ERRORS = ["/metrics/error/object_rot/**", "/metrics/error/wrist_rot/**"]
CONTACT_AND_PHASE = ["/metrics/contact/**", "/metrics/phase"]
PLAUSIBILITY_VIEWS = {
    "hand-obj (m)": ["hand_object_depth_m", "hand_gap_m"],
    "floor, supp (m)": ["body_floor_depth_m", "object_support_depth_m"],
    "feet (m, m/s)": ["foot_height_m", "foot_skate_speed_m_s"],
    "jerk (m/s^3)": ["body_jerk_m_s3", "object_jerk_m_s3"],
    "floating": ["object_float"],
}
"""Plausibility metrics (``/metrics/plausibility/<metric>/**``) per view: at most 2 metrics (4 series, reference
and simulation), so that a legend shows every name at a 900-pixel window (a view of 8 series showed 4 of them);
within a view the first metric is drawn orange (reference) / blue (simulation), the second brown / cyan
(:func:`wristmimic.view.record.plausibility_color`)."""


def clip_axis(num_frames: int | None) -> rrb.TimeAxis | None:
    """An x axis spanning frames 0..num_frames-1 of the ``frame`` timeline, so that series that end early (an
    episode that terminated) are seen against the whole clip; None: rerun's default (the data's extent)."""
    if not num_frames:
        return None
    span = rrb.TimeRange(
        start=rrb.TimeRangeBoundary.absolute(seq=0), end=rrb.TimeRangeBoundary.absolute(seq=max(num_frames - 1, 1))
    )
    return rrb.TimeAxis(view_range=span)


def make_blueprint(
    with_sim: bool,
    hidden: list[str] | None = None,
    fps: float = 30.0,
    num_frames: int | None = None,
    plausibility: bool = False,
    reward: bool = True,
) -> rrb.Blueprint:
    """A 3D view of ``/ref/**`` (and ``/sim/**``, ``/episode/**``) above the info text, beside time-series views
    of ``/metrics/**`` (x axis: the whole clip of ``num_frames``); ``plausibility``: tabs of the plausibility
    series; ``reward``: a reward view (with the simulation; an exported rollout has no reward, and an empty view
    took the height the legends need).

    ``hidden``: entity paths (subtrees) that start hidden in the 3D view, e.g. collision hulls.
    """
    contents = ["/ref/**", "/sim/**", "/episode/**"] if with_sim else ["/ref/**"]
    overrides = {p: rrb.EntityBehavior(visible=False) for p in hidden or []}
    scene = rrb.Spatial3DView(
        name="reference vs simulation" if with_sim else "reference", origin="/", contents=contents, overrides=overrides
    )
    axis = clip_axis(num_frames)

    def series(name: str, contents: list[str]) -> rrb.TimeSeriesView:
        return rrb.TimeSeriesView(name=name, origin="/metrics", contents=contents, axis_x=axis)

    plots: list[rrb.Container | rrb.View] = []
    if with_sim:
        plots += [
            series("position error (m)", POSITION_ERRORS),
            series("rotation error (deg)", ROTATION_ERRORS),
        ]
        plots += [series("reward", ["/metrics/reward"])] if reward else []
    plots.append(series("contact and phase", CONTACT_AND_PHASE))
    if plausibility:
        views = [
            series(name, [f"/metrics/plausibility/{m}/**" for m in metrics])
            for name, metrics in PLAUSIBILITY_VIEWS.items()
        ]
        plots.append(rrb.Tabs(*views, name="plausibility"))
    text = rrb.Tabs(rrb.TextDocumentView(name="info", origin="/info"), rrb.TextLogView(name="events", origin="/events"))
    # the info panel under the 3D view, so the plots get the column's height: stacked with them, a 900-pixel
    # window left each plot ~100 pixels and its legend showed only 3 of its 4 names (seen in Chromium)
    return rrb.Blueprint(
        rrb.Horizontal(rrb.Vertical(scene, text, row_shares=[4, 1]), rrb.Vertical(*plots), column_shares=[3, 2]),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        rrb.TimePanel(state="expanded", timeline="frame", fps=fps),
    )
