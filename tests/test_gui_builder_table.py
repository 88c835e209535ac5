"""The builder reads like a table (issue 36 item 3), in Chromium at 1024 and 1440 px.

Each heading sits over its column (bounding boxes); no number in a box is cut (the box's
scrollWidth fits its clientWidth), whether typed ("-1.547337813e-09", "671.83") or
filled from the catalog; the link table shows each parameter's value in mm or degrees;
a field is sent once per edit (on Enter), not once per key.
"""

from __future__ import annotations

from tests.test_gui import _field, browser, gui_url  # noqa: F401 (fixtures)

_CUT = """() => [...document.querySelectorAll('#form-body input')]
    .filter(i => i.scrollWidth > i.clientWidth + 1).map(i => i.id + '=' + i.value)"""
_COLUMNS = """() => {
  const t = document.querySelector('#joint-table');
  const left = e => Math.round(e.getBoundingClientRect().left);
  const heads = [...t.querySelectorAll('thead th')].map(left);
  const rows = [...t.querySelectorAll('tr.joint-row')].map(r => [...r.children].map(left));
  return {heads, rows};
}"""


def _open(browser, url: str, width: int):  # noqa: F811
    context = browser.new_context(viewport={"width": width, "height": 900})
    pg = context.new_page()
    errors: list[str] = []
    pg.on("pageerror", lambda e: errors.append(str(e)))
    pg.goto(url)
    pg.wait_for_selector("#joint-table input", timeout=60_000)
    return context, pg, errors


def _enter(pg, row, key: str, value: str) -> None:
    box = pg.locator(_field(row, key))
    box.fill(value)
    box.press("Enter")


def _aligned(pg) -> None:
    """Every row's cells start where their column's heading starts (within a pixel)."""
    boxes = pg.evaluate(_COLUMNS)
    assert len(boxes["rows"]) == 7  # six joints and the TCP
    for cells in boxes["rows"]:
        assert len(cells) == len(boxes["heads"])
        assert all(abs(c - h) <= 1 for c, h in zip(cells, boxes["heads"], strict=True)), (cells, boxes)


def test_headings_over_their_columns_and_no_number_cut(browser, gui_url):  # noqa: F811
    context, pg, errors = _open(browser, gui_url, 1024)
    try:
        assert pg.locator(_field("tcp", "tz")).input_value() == "100"
        assert pg.evaluate(_CUT) == []  # the start form at 1024 px: TCP z "100" in full
        pg.locator("#catalog-robot input[value='ur10']").check()
        pg.locator("#builder-count").get_by_text("= 30").wait_for(timeout=60_000)
        _enter(pg, 1, "pz", "671.83")
        _enter(pg, 2, "py", "-1.547337813e-09")
        pg.locator("#builder-links", has_text="671.83 mm").wait_for(timeout=30_000)
        for width in (1024, 1440):
            pg.set_viewport_size({"width": width, "height": 900})
            assert pg.evaluate(_CUT) == [], width
            _aligned(pg)
        # the link table: names, equations and the values in mm / degrees
        links = pg.locator("#builder-links").inner_text()
        assert "d1 = 671.83 mm" in links and "a2 = 612 mm" in links and "alpha1 = 90°" in links
        assert "Rz(theta1) · Tz(d1)" in links
        assert not errors, errors
    finally:
        context.close()


def test_a_field_is_sent_once_per_edit_not_per_key(browser, gui_url):  # noqa: F811
    context, pg, errors = _open(browser, gui_url, 1440)
    sent: list[str] = []
    pg.on(
        "request",
        lambda r: sent.append(r.post_data or "") if "_dash-update-component" in r.url else None,
    )
    try:
        box = pg.locator(_field("tcp", "tz"))
        box.click()
        box.press("End")
        pg.keyboard.type("0.25", delay=30)  # four keys
        pg.wait_for_timeout(300)
        assert not [s for s in sent if "builder-view" in s]  # nothing rebuilt while typing
        box.press("Enter")
        pg.locator("#builder-links", has_text="1000.25 mm").wait_for(timeout=30_000)
        assert len([s for s in sent if "builder-view" in s]) == 1
        assert not errors, errors
    finally:
        context.close()
