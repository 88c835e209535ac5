"""The builder's joint sliders (issue 36 item 3), in Chromium: one slider per joint within its
limits (degrees / mm); moving one redraws the 3D view at the new pose (the tool point moves)
with one request that neither reads nor builds the form again."""

from __future__ import annotations

import json

import numpy as np

from robocal.apps.gui.pose_sliders import joint_values_si, slider_range
from tests.test_gui import browser, gui_url  # noqa: F401 (fixtures)

# the chain's last point as drawn (plotly's decoded trace: the figure sends numpy arrays packed)
_TOOL = """() => { const d = document.querySelector('#builder-view .js-plotly-plot')._fullData[0];
  const n = d.x.length - 1; return [d.x[n], d.y[n], d.z[n]].map(Number); }"""


def test_slider_ranges_are_the_limits_in_degrees_and_mm():
    assert slider_range("revolute", (-np.pi / 2, np.pi / 3)) == (-90.0, 60.0)
    assert slider_range("revolute", (-np.inf, np.inf)) == (-180.0, 180.0)
    assert slider_range("prismatic", (-0.2, 0.35)) == (-200.0, 350.0)
    assert slider_range("prismatic", (-np.inf, np.inf)) == (-1000.0, 1000.0)


def test_moving_a_slider_moves_the_tool_without_a_rebuild(browser, gui_url):  # noqa: F811
    context = browser.new_context(viewport={"width": 1440, "height": 900})
    pg = context.new_page()
    errors: list[str] = []
    pg.on("pageerror", lambda e: errors.append(str(e)))
    try:
        pg.goto(gui_url)
        pg.wait_for_selector("#joint-table input", timeout=60_000)
        pg.locator("#catalog-robot input[value='ur10']").check()
        pg.locator("#builder-count").get_by_text("= 30").wait_for(timeout=60_000)
        sliders = pg.locator("#builder-sliders .dash-slider-root")
        sliders.nth(5).wait_for(timeout=30_000)
        assert sliders.count() == 6  # one per joint of the UR10
        before = pg.evaluate(_TOOL)
        sent: list[dict] = []
        pg.on(
            "request",
            lambda r: (
                sent.append(json.loads(r.post_data or "{}")) if "_dash-update-component" in r.url else None
            ),
        )
        thumb = pg.locator("#builder-sliders .dash-slider-thumb").nth(1)  # shoulder: moves the tool most
        with pg.expect_response(lambda r: "_dash-update-component" in r.url, timeout=30_000):
            thumb.press("End")  # to the upper end: +180°
        b = json.dumps(before)
        moved = (
            f"() => {{ const t = ({_TOOL})(), b = {b}; return t.some((v, i) => Math.abs(v - b[i]) > 1); }}"
        )
        pg.wait_for_function(moved, timeout=30_000)
        after = pg.evaluate(_TOOL)
        assert np.linalg.norm(np.subtract(after, before)) > 100.0  # mm: the tool moved
        outputs = " ".join(str(s.get("output", "")) for s in sent)
        assert sent and "builder-view.figure" in outputs
        # no request of the form's callback (its check and build): nothing about the links table
        assert "builder-links" not in outputs and "form-body" not in outputs
        assert "posed" in pg.locator("#builder-view .gtitle").text_content()
        assert not errors, errors
    finally:
        context.close()


def test_slider_values_become_radians_and_metres():
    class _Model:
        joint_types = ("revolute", "prismatic")

    class _Result:
        model = _Model()

    q = joint_values_si(_Result(), [90.0, 250.0])  # type: ignore[arg-type]
    assert np.allclose(q, [np.pi / 2, 0.25])
    assert np.allclose(joint_values_si(_Result(), [None, None]), 0.0)  # type: ignore[arg-type]
