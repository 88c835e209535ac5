"""The pose planning page: ``robocal poses`` in the browser.

Choose the robot, the method (random, optimal by an observability index O1-O5 from a random
pool, the ISO 9283 poses P1-P5, the thesis' diagonal planes), N and the seed; the page shows
the observability indices of the set (and of the pool's first N for ``optimal``), the planned
tool points in 3D in the order they are measured, and hands out the poses CSV that
``robocal poses`` writes (:func:`robocal.measure.poses.write_poses`, rad/m).  The selection
is ``robocal poses``' planner (:func:`robocal.identify.pose_plan.plan_poses`)."""

from __future__ import annotations

import dataclasses
import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from dash import Dash, Input, Output, State, dcc, html, no_update

from robocal.apps.gui.calibrate_views import parse_float, radio, row, text_input
from robocal.choices import INDEX_NAMES, POSE_METHODS, IndexName

if TYPE_CHECKING:
    from robocal.identify.pose_plan import PosePlan

__all__ = ["MAX_GUI_POOL", "MAX_GUI_POSES", "layout", "plan_poses", "poses_csv", "register"]

#: the page plans at most this many poses from a pool of at most this many (the command line
#: goes further); a larger request is refused by its control's name
MAX_GUI_POSES = 5000
MAX_GUI_POOL = 20000

_INDICES: tuple[IndexName, ...] = INDEX_NAMES


def layout(catalog: Sequence[str]) -> html.Div:
    """The planning page."""
    controls = html.Fieldset(
        [
            html.Legend("poses to measure"),
            row("robot", radio("plan-robot", tuple(catalog), catalog[0] if catalog else "")),
            row("method", radio("plan-method", ("random", "optimal", "iso9283", "diagonal"), "optimal")),
            row("poses", text_input("plan-n", "30", "6em"), "N (iso9283: always P1..P5; diagonal: 118)"),
            row("index", radio("plan-index", _INDICES, "O1"), "optimal: the observability index maximised"),
            row("pool", text_input("plan-pool", "2000", "6em"), "optimal: random candidates to choose from"),
            row("seed", text_input("plan-seed", "0", "4em")),
            html.Div(
                [
                    html.Button("plan", id="plan-run", className="primary"),
                    html.Button("download poses CSV", id="plan-download-button"),
                ],
                className="toolbar",
            ),
            dcc.Loading(html.Div(id="plan-summary", className="message")),
        ]
    )
    return html.Div(
        [
            html.Div([controls, html.Div(id="plan-indices")], className="left"),
            html.Div(html.Div(id="plan-view"), className="right"),
            dcc.Store(id="plan-store"),
            dcc.Download(id="plan-download"),
        ],
        className="page",
    )


def _whole(text: str | None, what: str, default: int, largest: int) -> int:
    value = parse_float(text, what)
    if value is None:
        return default
    if value != int(value) or not 1 <= value <= largest:
        raise ValueError(f"{what}: a whole number from 1 to {largest}, not {text!r}")
    return int(value)


def plan_poses(robot: str, method: str, n: int, index: IndexName, pool: int, seed: int) -> PosePlan:
    """The poses ``robocal poses ROBOT --method METHOD --n N --index INDEX --pool POOL --seed
    SEED`` writes (position rows; :func:`robocal.identify.pose_plan.plan_poses`, the command's
    planner) with the set's observability indices; ValueError naming the page's control."""
    from robocal.identify.pose_plan import plan_indices
    from robocal.identify.pose_plan import plan_poses as plan
    from robocal.model.catalog import find_model

    if method == "optimal" and pool < n:
        raise ValueError(f"pool: {pool} candidates cannot give {n} poses; raise the pool")
    model = find_model(robot)
    found = plan(model, method, n, seed=seed, index=index, pool=pool)
    if found.indices:
        return found
    return dataclasses.replace(found, indices=plan_indices(model, found.q))


def _indices_table(plan: PosePlan) -> html.Table:
    heads = ["index", "this set"] + (["the pool's first N"] if plan.reference else [])
    body = [
        html.Tr(
            [html.Td(k), html.Td(f"{plan.indices[k]:.4g}", className="num")]
            + ([html.Td(f"{plan.reference[k]:.4g}", className="num")] if plan.reference else [])
        )
        for k in _INDICES
    ]
    return html.Table(
        [html.Thead(html.Tr([html.Th(h) for h in heads])), html.Tbody(body)], id="plan-index-table"
    )


def _figure(plan: PosePlan, robot: str) -> Any:
    """The tool points (mm, robot base) in the order they are measured."""
    import plotly.graph_objects as go

    from robocal.model.catalog import find_model

    points = find_model(robot).fk(plan.q)[:, :3, 3] * 1e3
    fig = go.Figure(
        go.Scatter3d(
            x=points[:, 0],
            y=points[:, 1],
            z=points[:, 2],
            mode="markers+lines",
            name="poses",
            marker={
                "size": 3,
                "color": np.arange(len(points)),
                "colorscale": "Viridis",
                "colorbar": {"title": "order"},
            },
            line={"color": "#999", "width": 1},
            text=[f"pose {i + 1}" for i in range(len(points))],
        )
    )
    fig.update_layout(
        title=f"{len(points)} planned tool points (mm, robot base), in measuring order",
        height=560,
        margin={"l": 0, "r": 0, "t": 40, "b": 0},
        # few ticks and the camera a little farther out: at 1024 px the corner's tick labels
        # ran into each other and the z axis was cut at the bottom
        scene={
            "aspectmode": "data",
            **{f"{a}axis": {"title": f"{a} mm", "nticks": 5} for a in "xyz"},
            "camera": {"eye": {"x": 1.6, "y": 1.6, "z": 1.1}},
        },
    )
    return fig


def register(app: Dash) -> None:
    """The planning callbacks: plan (summary, indices, 3D view) and the poses CSV download."""

    @app.callback(
        Output("plan-summary", "children"),
        Output("plan-indices", "children"),
        Output("plan-view", "children"),
        Output("plan-store", "data"),
        Input("plan-run", "n_clicks"),
        State("plan-robot", "value"),
        State("plan-method", "value"),
        State("plan-n", "value"),
        State("plan-index", "value"),
        State("plan-pool", "value"),
        State("plan-seed", "value"),
        prevent_initial_call=True,
    )
    def plan(_n, robot, method, n, index, pool, seed):
        try:
            if method not in POSE_METHODS or index not in _INDICES:
                raise ValueError(f"method {method!r}, index {index!r}: choose them with the buttons")
            count = _whole(n, "poses", 30 if method != "diagonal" else 118, MAX_GUI_POSES)
            candidates = _whole(pool, "pool", 2000, MAX_GUI_POOL)
            s = parse_float(seed, "seed")
            result = plan_poses(robot, method, count, index, candidates, 0 if s is None else int(s))
        except ValueError as err:
            return html.Span(str(err), className="error", id="plan-error"), "", "", None
        summary = f"{len(result.q)} poses of {result.metadata['robot']} ({method})"
        lines = [*result.notes, *(f"not identifiable: {d}" for d in result.not_identifiable)]
        notes = [html.Div(line, className="hint") for line in lines]
        graph = dcc.Graph(figure=_figure(result, robot), id="plan-3d", config={"displaylogo": False})
        stored = {"robot": robot, "q": result.q.tolist(), "metadata": result.metadata}
        return (
            html.Span(summary, className="ok", id="plan-ok"),
            [_indices_table(result), *notes],
            graph,
            stored,
        )

    @app.callback(
        Output("plan-download", "data"),
        Input("plan-download-button", "n_clicks"),
        State("plan-store", "data"),
        prevent_initial_call=True,
    )
    def download(_n, stored):
        if not stored:
            return no_update
        text = poses_csv(stored["robot"], stored["q"], stored["metadata"])
        return {"content": text, "filename": "poses.csv"}


def poses_csv(robot: str, q: list, metadata: dict[str, str]) -> str:
    """The poses CSV ``robocal poses`` writes for ``q`` (rad/m) of the catalog's ``robot``."""
    from robocal.measure.poses import write_poses
    from robocal.model.catalog import find_model

    model = find_model(robot)
    with tempfile.TemporaryDirectory(prefix="robocal-gui-poses-") as tmp:
        path = write_poses(
            Path(tmp) / "poses.csv", np.asarray(q, dtype=float), model=model, metadata=metadata
        )
        return path.read_text(encoding="utf-8")
