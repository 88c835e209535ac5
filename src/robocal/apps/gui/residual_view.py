"""The measured points and the calibrated model's errors at them in 3D (device frame, mm).

Each measured point is a marker coloured by its position error (the menu switches the
calibration poses between the start model's and the calibrated model's errors); a line from
each point shows the calibrated model's error vector (predicted - measured), magnified so the
largest is a tenth of the cloud's size (the factor is in the title).  Held-out points are
diamonds.  The data come from the run's ``errors.json`` (:func:`robocal.apps.gui.jobs`)."""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["MAX_HELD_OUT_SHOWN", "arrow_scale", "residual_figure"]

#: at most this many held-out points are drawn (every k-th row; the statistics use them all)
MAX_HELD_OUT_SHOWN = 2000


def arrow_scale(points_mm: np.ndarray, errors_mm: np.ndarray) -> float:
    """The magnification that draws the largest error as a tenth of the cloud's largest extent."""
    extent = float(np.ptp(points_mm, axis=0).max()) if len(points_mm) > 1 else 1.0
    largest = float(np.linalg.norm(errors_mm, axis=1).max()) if len(errors_mm) else 0.0
    return 0.1 * extent / largest if largest > 0 and extent > 0 else 1.0


def _arrows(points: np.ndarray, errors: np.ndarray, scale: float) -> tuple[list, list, list]:
    """The line segments point -> point + scale * error, separated by gaps (None)."""
    ends = points + scale * errors
    xyz: tuple[list, list, list] = ([], [], [])
    for p, e in zip(points, ends, strict=True):
        for k in range(3):
            xyz[k].extend((float(p[k]), float(e[k]), None))
    return xyz


def residual_figure(sets: dict[str, Any]) -> Any:
    """The 3D figure of ``errors.json``'s sets (None when the run recorded no points)."""
    import plotly.graph_objects as go

    points = sets.get("points") or {}
    train = points.get("train")
    if not train:
        return None
    held = points.get("held_out")
    p_train, e_train = np.asarray(train["measured_mm"]), np.asarray(train["error_mm"])
    all_p = np.vstack([p_train, np.asarray(held["measured_mm"])]) if held else p_train
    all_e = np.vstack([e_train, np.asarray(held["error_mm"])]) if held else e_train
    scale = arrow_scale(all_p, all_e)
    after = np.linalg.norm(e_train, axis=1)
    before = np.asarray((sets.get("before") or {}).get("errors_mm", after))
    top = float(max(before.max(), after.max(), 1e-9))
    marker = {"size": 3, "colorscale": "Viridis", "cmin": 0.0, "colorbar": {"title": "mm"}}
    traces = [
        go.Scatter3d(
            x=p_train[:, 0], y=p_train[:, 1], z=p_train[:, 2], mode="markers", name="calibration poses",
            marker=marker | {"color": after, "cmax": top}, text=[f"{v:.4f} mm" for v in after],
        ),
        go.Scatter3d(**_line(p_train, e_train, scale, "error after, calibration poses", "#d62728")),
    ]  # fmt: skip
    if held:
        p_held, e_held = np.asarray(held["measured_mm"]), np.asarray(held["error_mm"])
        every = slice(
            None, None, -(-len(p_held) // MAX_HELD_OUT_SHOWN)
        )  # evenly thinned: the browser stays quick
        p_held, e_held = p_held[every], e_held[every]
        err = np.linalg.norm(e_held, axis=1)
        traces.append(go.Scatter3d(
            x=p_held[:, 0], y=p_held[:, 1], z=p_held[:, 2], mode="markers", name="held-out poses",
            marker=marker | {"color": err, "cmax": top, "symbol": "diamond", "showscale": False},
            text=[f"{v:.4f} mm" for v in err],
        ))  # fmt: skip
        traces.append(go.Scatter3d(**_line(p_held, e_held, scale, "error, held-out poses", "#ff7f0e")))
    fig = go.Figure(traces)
    fig.update_layout(
        title=f"measured points (mm, device frame), coloured by position error; error lines ×{scale:.0f}",
        height=520,
        margin={"l": 0, "r": 0, "t": 40, "b": 0},
        scene={"aspectmode": "data", "xaxis_title": "x mm", "yaxis_title": "y mm", "zaxis_title": "z mm"},
        updatemenus=[_colour_menu(before, after, top)],
        legend={"x": 0, "y": 1},
    )
    return fig


def _line(points: np.ndarray, errors: np.ndarray, scale: float, name: str, colour: str) -> dict[str, Any]:
    x, y, z = _arrows(points, errors, scale)
    return {"x": x, "y": y, "z": z, "mode": "lines", "name": name, "line": {"color": colour, "width": 2}}


def _colour_menu(before: np.ndarray, after: np.ndarray, top: float) -> dict[str, Any]:
    """Buttons colouring the calibration poses by the start model's or the calibrated one's error."""
    return {
        "type": "buttons",
        "direction": "right",
        "x": 0.0,
        "y": -0.02,
        "xanchor": "left",
        "buttons": [
            {"label": "after (calibrated)", "method": "restyle",
             "args": [{"marker.color": [after.tolist()], "text": [[f"{v:.4f} mm" for v in after]]}, [0]]},
            {"label": "before (start model)", "method": "restyle",
             "args": [{"marker.color": [before.tolist()], "text": [[f"{v:.4f} mm" for v in before]]}, [0]]},
        ],
    }  # fmt: skip
