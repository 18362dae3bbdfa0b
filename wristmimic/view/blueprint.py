"""The layout a recording opens with: the 3D scene beside time series of errors, contacts and phases."""

from __future__ import annotations

import rerun.blueprint as rrb

# metric entity groups (see wristmimic.view.record for what each holds)
POSITION_ERRORS = ["/metrics/error/object_pos/**", "/metrics/error/wrist_pos/**", "/metrics/error/body_pos/**"]
ROTATION_ERRORS = ["/metrics/error/object_rot/**", "/metrics/error/wrist_rot/**"]
CONTACT_AND_PHASE = ["/metrics/contact/**", "/metrics/phase"]


def make_blueprint(with_sim: bool, hidden: list[str] | None = None, fps: float = 30.0) -> rrb.Blueprint:
    """A 3D view of ``/ref/**`` (and ``/sim/**``), time-series views of ``/metrics/**`` and the info text.

    ``hidden``: entity paths (subtrees) that start hidden in the 3D view, e.g. collision hulls.
    """
    contents = ["/ref/**", "/sim/**"] if with_sim else ["/ref/**"]
    overrides = {p: rrb.EntityBehavior(visible=False) for p in hidden or []}
    scene = rrb.Spatial3DView(
        name="reference vs simulation" if with_sim else "reference", origin="/", contents=contents, overrides=overrides
    )
    plots: list[rrb.View] = []
    if with_sim:
        plots += [
            rrb.TimeSeriesView(name="position error (m)", origin="/metrics", contents=POSITION_ERRORS),
            rrb.TimeSeriesView(name="rotation error (deg)", origin="/metrics", contents=ROTATION_ERRORS),
            rrb.TimeSeriesView(name="reward", origin="/metrics", contents=["/metrics/reward"]),
        ]
    plots.append(rrb.TimeSeriesView(name="contact and phase", origin="/metrics", contents=CONTACT_AND_PHASE))
    text = rrb.Tabs(rrb.TextDocumentView(name="info", origin="/info"), rrb.TextLogView(name="events", origin="/events"))
    return rrb.Blueprint(
        rrb.Horizontal(scene, rrb.Vertical(*plots, text), column_shares=[3, 2]),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        rrb.TimePanel(state="expanded", timeline="frame", fps=fps),
    )
