"""Seed 003 §5.5.2: the pen and potentiometer check — the trace and the potentiometer as a
device, and the circle/line procedure on the virtual Katana before and after eq. 5.22."""

import math

import numpy as np
import pytest

from robocal import spatial
from robocal.measure.pen_trace import PRELOAD, across_deviation, pen_trace
from robocal.measure.plates import PenOnPaper

RADIUS = 0.1


def _paper(tilt_deg: float = 45.0) -> PenOnPaper:
    T = spatial.homogeneous(spatial.rotx(math.radians(tilt_deg)), [0.05, -0.3, 0.3])
    return PenOnPaper(T_device_base=spatial.inverse(T))


def _printed(n: int = 3601) -> np.ndarray:
    a = np.linspace(0, 2 * np.pi, n)
    return RADIUS * np.stack([np.cos(a), np.sin(a)], axis=1)


def _on_paper(pen: PenOnPaper, local: np.ndarray) -> np.ndarray:
    """Paper-frame points ``(n, 3)`` in the robot base."""
    T = pen.T_base_device
    return local @ T[:3, :3].T + T[:3, 3]


def test_the_potentiometer_reads_the_out_of_plane_error_and_shows_a_lift():
    pen = _paper()
    a = np.linspace(0, 2 * np.pi, 50, endpoint=False)
    z = 0.6e-3 * np.sin(3 * a)  # off the paper by up to 0.6 mm
    z[7] = 1.5e-3  # beyond the 1 mm preload: the pen lifts
    local = np.stack([RADIUS * np.cos(a), RADIUS * np.sin(a), z], axis=1)
    trace = pen_trace(pen, _on_paper(pen, local))
    touching = ~trace.lifted
    assert trace.lifted.tolist() == [i == 7 for i in range(50)]
    assert np.allclose(trace.potentiometer[touching], -z[touching], atol=1e-12)
    assert trace.potentiometer[7] == pytest.approx(-PRELOAD) and np.isnan(trace.xy[7]).all()
    assert np.allclose(trace.xy[touching], local[touching, :2], atol=1e-12)
    with pytest.raises(ValueError, match="bottoms out"):
        pen_trace(pen, _on_paper(pen, np.array([[0.0, 0.0, -0.0095]])))
    with pytest.raises(ValueError, match="sheet"):
        pen_trace(pen, _on_paper(pen, np.array([[0.2, 0.0, 0.0]])))


def test_the_trace_shows_the_error_across_the_path_and_not_along_it():
    pen = _paper()
    a = np.linspace(0, 2 * np.pi, 200, endpoint=False)
    radial = 0.3e-3 * np.cos(2 * a)
    late = a - 0.5e-3 / RADIUS * (1 + np.sin(a))  # up to 1 mm behind along the circle
    local = np.stack(
        [(RADIUS + radial) * np.cos(late), (RADIUS + radial) * np.sin(late), np.zeros_like(a)], axis=1
    )
    seen = across_deviation(pen_trace(pen, _on_paper(pen, local)).xy, _printed())
    assert np.allclose(-seen, radial, atol=2e-6)  # the printed circle runs counter-clockwise: + inward
    along = np.abs(late - a) * RADIUS
    assert along.max() > 0.9e-3 and np.abs(seen).max() < 0.31e-3


@pytest.fixture(scope="module")
def katana_check():
    pytest.importorskip("pinocchio")
    from robocal.experiments.seed003_pen import pen_experiment

    return pen_experiment(n_samples=120)


def test_compensation_shrinks_what_the_pen_sees_by_the_truths_factor(katana_check):
    """On the virtual Katana (Table 3.2 + Table 5.2) the circle's across-deviation the trace
    shows and the out-of-plane error the potentiometer reads follow the truth sample by
    sample before compensation; after it both fall by the truth's factor down to the
    readings' noise (0.1 mm trace, 0.01 mm potentiometer)."""
    for name in ("circle", "line"):
        before, after = katana_check["paths"][name]["before"], katana_check["paths"][name]["after"]
        ok = np.isfinite(before["_trace_across"])
        assert np.abs(before["_trace_across"][ok] - before["_true_across"][ok]).max() < 0.5e-3
        spread = before["_true_across"][ok].std()  # the correlation the trace's 0.1 mm noise allows
        allowed = spread / math.hypot(spread, 0.1e-3)
        assert np.corrcoef(before["_trace_across"][ok], before["_true_across"][ok])[0, 1] > allowed - 0.1
        touching = before["_potentiometer"] > -1e-3 + 1e-9
        gap = before["_potentiometer"][touching] + before["_true_out"][touching]
        assert np.abs(gap).max() < 5 * 0.01e-3
        assert after["error_3d_mm"] < before["error_3d_mm"] / 10
        assert after["true_out_of_plane_mm"] < before["true_out_of_plane_mm"] / 10
        # what the pen shows after: its own noise (mean |N(0, σ)| = 0.8 σ), not the truth's tiny error
        assert after["trace_across_mm"] == pytest.approx(0.08, rel=0.35)
        assert after["potentiometer_mm"] == pytest.approx(
            math.hypot(0.008, after["true_out_of_plane_mm"]), rel=0.5
        )
        assert before["trace_across_mm"] > 2 * after["trace_across_mm"]


def test_the_reproduction_section_reports_what_the_check_cannot_give(katana_check):
    from robocal.experiments.reproductions import _section_pen

    section = _section_pen(katana_check)
    text = " ".join(r.quantity + r.why for r in section.rows) + " ".join(section.notes)
    assert "visually recognise" in text and "along the path" in text and "where the paper sits" in text
    assert all(r.seed in ("visual only", "—") for r in section.rows)


def test_the_reproduction_document_section_is_current():
    from pathlib import Path

    pytest.importorskip("pinocchio")
    from robocal.experiments.reproductions import _section_pen, render_markdown
    from robocal.experiments.seed003_pen import pen_experiment, public

    section = _section_pen(public(pen_experiment()))
    generated = render_markdown("seed003", "x", [section]).split(f"## {section.title}\n", 1)[1].strip()
    doc = (Path(__file__).resolve().parents[1] / "docs" / "reproductions" / "seed003.md").read_text("utf-8")
    assert f"## {section.title}\n\n{generated}\n" in doc, "regenerate with robocal reproduce all --md ..."
