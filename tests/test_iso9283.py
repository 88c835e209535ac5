"""ISO 9283 characteristics: formulas on designed arrays, the log format, logs whose
characteristics are known by construction, and the command."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from typer.testing import CliRunner

import robocal.evaluate.iso9283.characteristics as iso
from robocal import spatial
from robocal.cli import app
from robocal.evaluate.iso9283.log import Iso9283Log, Iso9283LogError, read_iso9283_log, write_iso9283_log
from robocal.evaluate.iso9283.report import evaluate_log, results_html
from robocal.evaluate.iso9283.sim import LogErrors, LogPlan, simulate_log
from robocal.evaluate.metrics import path_accuracy
from robocal.measure.cube import Cube
from robocal.model.catalog import robot

runner = CliRunner()
DOWN = np.diag([1.0, -1.0, -1.0])


# ------------------------------------------------------------------ formulas
def test_multidirectional_variation_is_largest_barycentre_distance():
    rng = np.random.default_rng(0)
    centres = np.array([[0, 0, 0], [3e-5, 0, 0], [0, 4e-5, 0]])
    groups = []
    for c in centres:
        e = rng.normal(0, 1e-5, (8, 3))
        groups.append(c + e - e.mean(axis=0))  # barycentre exactly c
    mv = iso.multidirectional_variation(groups)
    assert mv.vAP == pytest.approx(5e-5, abs=1e-12)  # |(3, -4, 0)| e-5
    assert set(mv.pair) == {1, 2}
    with pytest.raises(ValueError, match="2 approach directions"):
        iso.multidirectional_variation(groups[:1])


def test_multidirectional_orientation():
    frames = []
    for da in (0.0, 0.001, -0.002):
        R = spatial.euler_to_matrix(np.array([math.pi + da, 0.0, 0.0]), "xyz")
        frames.append(np.repeat(spatial.homogeneous(R, np.zeros(3))[None], 3, axis=0))
    mv = iso.multidirectional_variation(frames)
    assert mv.vAP_abc[0] == pytest.approx(0.003, abs=1e-9)  # across ±π, wrapped
    assert mv.vAP_abc[1:] == pytest.approx([0, 0], abs=1e-9)


def test_distance_accuracy_and_repeatability():
    c1, c2 = np.zeros(3), np.array([0.5, 0.0, 0.0])
    extra = np.array([1e-4, 2e-4, 3e-4, 2e-4])  # attained distance 0.5 + extra
    p1 = np.zeros((4, 3))
    p2 = np.column_stack([0.5 + extra, np.zeros(4), np.zeros(4)])
    d = iso.distance_characteristics(p1, p2, c1, c2)
    assert d.D_c == pytest.approx(0.5)
    assert pytest.approx(2e-4, abs=1e-12) == d.AD
    assert pytest.approx(3 * np.std(extra, ddof=1), abs=1e-12) == d.RD
    assert d.AD_xyz == pytest.approx([2e-4, 0, 0], abs=1e-12)
    short = iso.distance_characteristics(p1, np.column_stack([0.5 - extra, np.zeros((4, 2))]), c1, c2)
    assert pytest.approx(-2e-4, abs=1e-12) == short.AD  # signed: the robot travels short


def _settling_record(A: float, tau: float, hz: float, rate: float, T_move: float = 0.2):
    """A move of 50 mm along x ending at T_move, then s(t) = A e^{-t/τ} sin(2π f t)."""
    t = np.arange(0.0, T_move + 1.0, 1.0 / rate)
    lam = np.clip(t / T_move, 0, 1)
    x = -0.05 * (1 - lam)
    tt = np.maximum(t - T_move, 0.0)
    x = x + A * np.exp(-tt / tau) * np.sin(2 * np.pi * hz * tt)
    return t, np.column_stack([x, np.zeros_like(x), np.zeros_like(x)])


def test_stabilisation_time_and_overshoot_of_a_damped_oscillation():
    A, tau, hz, band, rate = 0.3e-3, 0.05, 8.0, 0.1e-3, 10_000.0
    t, p = _settling_record(A, tau, hz, rate)
    s = iso.stabilisation(t, p, 0.2, band, np.zeros(3))
    w = 2 * np.pi * hz
    tp = math.atan(w * tau) / w
    assert s.overshoot == pytest.approx(A * math.exp(-tp / tau) * math.sin(w * tp), abs=2e-8)
    # the last instant |s| > band, solved independently by bisection on the first lobe's falling side
    lo, hi = tp, math.pi / w
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if A * math.exp(-mid / tau) * math.sin(w * mid) > band else (lo, mid)
    assert s.time == pytest.approx(lo, abs=2.0 / rate)
    assert s.settled


def test_stabilisation_without_overshoot_and_unsettled():
    t, p = _settling_record(0.05e-3, 0.05, 8.0, 1000.0)  # oscillation smaller than the band
    s = iso.stabilisation(t, p, 0.2, 0.1e-3, np.zeros(3))
    assert s.time == 0.0 and s.overshoot == 0.0
    t, p = _settling_record(0.3e-3, 5.0, 8.0, 1000.0)  # still oscillating at the end
    s = iso.stabilisation(t, p, 0.2, 0.1e-3, np.zeros(3))
    assert not s.settled and math.isnan(s.time)
    with pytest.raises(ValueError, match="band"):
        iso.stabilisation(t, p, 0.2, 0.0)


def test_positioning_time_counts_from_the_start_of_the_move():
    t, p = _settling_record(0.3e-3, 0.05, 8.0, 10_000.0)
    tp = iso.positioning_time(t, p, 0.0, 0.1e-3, np.zeros(3))
    s = iso.stabilisation(t, p, 0.2, 0.1e-3, np.zeros(3))
    assert tp == pytest.approx(0.2 + s.time, abs=1e-3)


def test_drift_of_ap_and_rp():
    c = np.zeros(3)
    ring = 1e-5 * np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0]])  # l_j = 1e-5, S_l = 0
    first = np.array([1e-4, 0, 0]) + ring
    last = np.array([1.5e-4, 0, 0]) + 2 * ring
    d = iso.drift([first, last], c)
    assert d.dAP == pytest.approx(5e-5, abs=1e-12)
    assert d.dRP == pytest.approx(1e-5, abs=1e-12)  # RP 1e-5 -> 2e-5


def test_exchangeability():
    robots = [np.zeros((3, 3)), np.full((3, 3), 1e-4), np.array([[2e-4, 0, 0]] * 3)]
    e = iso.exchangeability(robots)
    assert pytest.approx(2e-4, abs=1e-12) == e.E  # robots 1 and 3 (robot 2 is sqrt(3)e-4 from both)
    assert set(e.pair) == {0, 2}


def _corner_path(rho: float, co: float, ds: float, bump: float = 0.05):
    """Attained path around a right-angle corner at the origin (in along +x, out along
    +y): a round-off arc of radius rho and an outward bump of height co after it."""
    s = np.arange(-0.1, 0.1 + ds / 2, ds)
    p = np.where(s[:, None] < 0, np.outer(s, [1, 0, 0]), np.outer(s, [0, 1, 0]))
    arc = np.abs(s) <= rho
    phi = (s[arc] + rho) / (2 * rho) * (np.pi / 2)
    centre = np.array([-rho, rho, 0.0])
    p[arc] = centre + rho * (-np.outer(np.cos(phi), [0, 1, 0]) + np.outer(np.sin(phi), [1, 0, 0]))
    after = (s > rho) & (s < rho + bump)
    p[after, 0] += co * np.sin(np.pi * (s[after] - rho) / bump)
    return p


def test_cornering_round_off_and_overshoot():
    rho, co = 5e-3, 0.3e-3
    paths = [_corner_path(rho, co, 1e-4), _corner_path(rho, 2 * co, 1e-4)]
    c = iso.cornering(np.zeros(3), [1, 0, 0], [0, 1, 0], 0.1, paths)
    assert pytest.approx([rho * (math.sqrt(2) - 1)] * 2, abs=1e-6) == c.CR
    assert pytest.approx([co, 2 * co], abs=1e-7) == c.CO
    sharp = iso.cornering(np.zeros(3), [1, 0, 0], [0, 1, 0], 0.1, [_corner_path(1e-9, 0.0, 1e-3)])
    assert sharp.CR[0] == pytest.approx(0.0, abs=1e-9) and sharp.CO[0] == 0.0


def test_path_speeds_and_velocity_characteristics():
    t = np.arange(0, 2, 0.001)
    p = np.outer(0.25 * t, [0.6, 0.8, 0.0])
    assert iso.path_speeds(t, p, 0.05) == pytest.approx(np.full(len(t), 0.25), rel=1e-9)
    speeds = [np.array([0.24, 0.26, 0.25]), np.array([0.25, 0.25, 0.25]), np.array([0.26, 0.27, 0.25])]
    pv = iso.path_velocity(speeds, 0.25)
    means = np.array([0.25, 0.25, 0.26])
    assert pytest.approx(100 * (means.mean() - 0.25) / 0.25) == pv.AV
    assert pytest.approx(3 * means.std(ddof=1)) == pv.RV
    assert pytest.approx(0.02) == pv.FV
    with pytest.raises(ValueError, match="commanded speed"):
        iso.path_velocity(speeds, 0.0)


def test_static_compliance():
    C = np.array([[2e-5, 1e-6, 0], [0, 3e-5, 0], [0, 0, 1e-5]])
    F = np.array([[50, 0, 0], [100, 0, 0], [-100, 0, 0], [0, 0, 80], [0, -40, 0]], dtype=float)
    sc = iso.static_compliance(F, F @ C.T)
    got = dict(zip(sc.directions, sc.compliance, strict=True))
    assert got["+x"] == pytest.approx(2e-5) and got["-x"] == pytest.approx(2e-5)
    assert got["+z"] == pytest.approx(1e-5)
    assert got["-y"] == pytest.approx(math.hypot(1e-6, 3e-5))
    with pytest.raises(ValueError, match="one base axis"):
        iso.static_compliance([[10.0, 10.0, 0.0]], [[0.0, 0.0, 0.0]])


def test_weaving_stroke_and_frequency_errors():
    t = np.arange(0, 10, 0.004)
    base = np.outer(0.01 * t, [1, 0, 0])
    across = np.array([0, 1, 0])
    cmd = base + np.outer(5e-3 * np.sin(2 * np.pi * 1.0 * t), across)
    att = base + np.outer(5e-3 * 1.03 * np.sin(2 * np.pi * 0.98 * t), across)
    w = iso.weaving(t, cmd, att)
    assert w.stroke_c == pytest.approx(0.01, rel=1e-3)
    assert pytest.approx(3.0, abs=0.1) == w.WS
    assert pytest.approx(-2.0, abs=0.02) == w.WF


def test_path_accuracy_on_reorientation():
    s = np.linspace(0, 0.5, 60)
    pts = np.outer(s, [1, 0, 0])
    abc_c = np.column_stack([np.full(60, math.pi), np.zeros(60), np.linspace(-0.5, 0.5, 60)])
    cmd = spatial.homogeneous(spatial.euler_to_matrix(abc_c, "xyz"), pts)
    offsets = [
        np.array([0.001, -0.002, 0.0005]) + d for d in (np.array([1e-4, 0, 0]), np.array([-1e-4, 0, 0]))
    ]
    attained = [
        spatial.homogeneous(spatial.euler_to_matrix(abc_c + o, "xyz"), pts + [0, 2e-4, 0]) for o in offsets
    ]
    pa = path_accuracy(cmd[::3], attained)
    assert pytest.approx(2e-4, abs=1e-9) == pa.AT
    assert pa.AT_abc == pytest.approx([0.001, 0.002, 0.0005], abs=1e-7)
    assert pa.RT_abc == pytest.approx([3 * np.std([1e-4, -1e-4], ddof=1), 0, 0], abs=1e-7)
    assert path_accuracy(pts[::3], [pts]).AT_abc is None  # positions only: unchanged behaviour


# ------------------------------------------------------------------ the log
def _static_log(targets: dict[str, np.ndarray], offsets: list[np.ndarray], test: str = "pose") -> Iso9283Log:
    """A log of single-sample visits: each cycle visits every target once."""
    rows = []
    for j, off in enumerate(offsets):
        for name, c in targets.items():
            rows.append((j + 1, name, c, c + off))
    n = len(rows)
    return Iso9283Log(
        source="<test>",
        conditions={"robot": "test"},
        time=np.arange(n, dtype=float),
        test=np.full(n, test),
        cycle=np.array([r[0] for r in rows]),
        target=np.array([r[1] for r in rows]),
        group=np.full(n, ""),
        position=np.array([r[3] for r in rows]),
        commanded=np.array([r[2] for r in rows]),
    )


def test_log_with_known_ap_rp_and_not_measured_reasons(tmp_path):
    r = 2e-5
    ring = [r * np.array(v) for v in ([1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1])]
    bias = np.array([1e-4, -2e-4, 2e-4])
    targets = {"P1": np.array([0.5, 0.0, 0.4]), "P2": np.array([0.6, 0.1, 0.3])}
    log = _static_log(targets, [bias + o for o in ring])
    path = write_iso9283_log(log, tmp_path / "log.csv")
    res = evaluate_log(read_iso9283_log(path))
    row = res.rows[0]
    assert row.measured
    for d in row.details:
        assert d["AP_mm"] == pytest.approx(0.3, abs=1e-6)  # |(0.1, -0.2, 0.2)| mm
        assert d["RP_mm"] == pytest.approx(0.02, abs=1e-6)  # every l_j = r, S_l = 0
    assert not res.rows[3].measured and "time record" in res.rows[3].summary  # single samples
    assert [r.measured for r in res.rows].count(True) == 1
    assert "test=weaving" in res.rows[13].summary


def _write(tmp_path, text: str):
    p = tmp_path / "bad.csv"
    p.write_text(text, encoding="utf-8")
    return p


HEADER = "time_s,test,cycle,target,x_mm,y_mm,z_mm,cmd_x_mm,cmd_y_mm,cmd_z_mm\n"


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("", "no header line"),
        ("# only: comments\n", "no header line"),
        (HEADER, "no data rows"),
        ("time_s,test,cycle,target,x_mm\n0,pose,1,P1,1\n", "missing column(s) y_mm"),
        (HEADER.replace("\n", ",x_m\n") + "0,pose,1,P1,1,2,3,1,2,3,4\n", "unknown column 'x_m'"),
        (HEADER + "0,pose,1,P1,1,abc,3,1,2,3\n", "row 2 column y_mm: 'abc' is not a finite number"),
        (HEADER + "0,pose,1,P1,1,,3,1,2,3\n", "row 2 column y_mm: empty"),
        (HEADER + "0,walk,1,P1,1,2,3,1,2,3\n", "row 2 column test: 'walk' is not one of"),
        (HEADER + "0,pose,1.5,P1,1,2,3,1,2,3\n", "row 2 column cycle"),
        (HEADER + "0,pose,1,,1,2,3,1,2,3\n", "row 2 column target: empty"),
        (
            HEADER + "1,pose,1,P1,1,2,3,1,2,3\n0.5,pose,1,P1,1,2,3,1,2,3\n",
            "row 3 column time_s: time goes back",
        ),
        (
            HEADER.replace("\n", ",a_deg\n") + "0,pose,1,P1,1,2,3,1,2,3,4\n",
            "orientation columns come all or none",
        ),
        ("# a: b\n" + HEADER + "0,pose,1,P1,1,2,3,1,2,nan\n", "row 3 column cmd_z_mm"),
        (HEADER + "0,pose,1,P1,1,2,3,1,2,3,9\n", "row 2: 11 fields, but the header has 10"),
        ("# a: b\n\n" + HEADER + "\n0,pose,1,P1,1,2\n", "row 5: 6 fields"),
        ("time_s," + HEADER, "row 1: duplicate column 'time_s'"),
        (HEADER.replace(",", ";"), "columns must be separated by commas"),
        (HEADER + '0,pose,1,"P1,1,2,3,1,2,3\n', "not a CSV table"),
        (HEADER + "0,pose,1,P1,1,2,3,1,2,3\x00\n", "row 2 column cmd_z_mm"),
    ],
)
def test_bad_logs_name_file_row_and_column(tmp_path, text, message):
    path = _write(tmp_path, text)
    with pytest.raises(Iso9283LogError) as err:
        read_iso9283_log(path)
    assert str(err.value).startswith(str(path))
    assert message in str(err.value)
    result = runner.invoke(app, ["iso9283", str(path)])
    assert result.exit_code == 2
    assert "Traceback" not in result.output
    assert result.exception is None or isinstance(result.exception, SystemExit)  # no traceback


def test_log_that_is_not_utf8(tmp_path):
    path = tmp_path / "bin.csv"
    path.write_bytes(b"\xff\xfe\x00garbage")
    result = runner.invoke(app, ["iso9283", str(path)])
    assert result.exit_code == 2 and "not UTF-8" in result.output


def test_missing_log_file(tmp_path):
    result = runner.invoke(app, ["iso9283", str(tmp_path / "none.csv")])
    assert result.exit_code == 2 and "no such file" in result.output


# ------------------------------------------------------------------ simulated, known by construction
ERRORS = LogErrors(repeatability=5e-6, noise=1e-6, angle_repeatability=math.radians(0.0005))
PLAN = LogPlan(
    cycles={
        "pose": 3,
        "multidirectional": 10,
        "distance": 10,
        "exchangeability": 10,
        "path": 5,
        "reorientation": 5,
        "cornering": 2,
        "velocity": 4,
        "positioning": 2,
        "compliance": 2,
        "weaving": 2,
    },
    drift_cycles=10,
    drift_hours=2.0,
    distances=(0.01, 0.1, 0.5),
)


@pytest.fixture(scope="module")
def simulated():
    cube = Cube(np.array([0.0, -0.64, 0.03]), 0.9)
    sim = simulate_log(robot("ur10"), errors=ERRORS, plan=PLAN, seed=3, cube=cube)
    return sim, {r.number: r for r in evaluate_log(sim.log).rows}


def test_simulated_log_measures_all_fourteen(simulated):
    _, rows = simulated
    assert all(r.measured for r in rows.values()), [r.summary for r in rows.values() if not r.measured]


def test_simulated_pose_characteristics(simulated):
    sim, rows = simulated
    truth = sim.truth
    for d in rows[1].details:
        k = int(d["pose"][1]) - 1
        assert d["AP_mm"] == pytest.approx(truth["AP_mm_deterministic"][k], abs=0.012)
        assert d["AP_abc_deg"] == pytest.approx(truth["bias_abc_deg"][k], abs=0.002)
    dt = 2.0 / PLAN.rate_hz
    for d in rows[4].details:
        assert d["time_s"] == pytest.approx(truth["stabilisation_time_s"], abs=dt)
    for d in rows[5].details:
        assert d["overshoot_mm"] == pytest.approx(truth["overshoot_mm"], abs=0.01)
    assert truth["overshoot_mm"] > 0.1  # the construction does overshoot the band
    for d in rows[2].details:
        assert d["vAP_mm"] == pytest.approx(truth["vAP_mm_expected"], abs=0.01)
    assert rows[3].details[0]["AD_mm"] == pytest.approx(truth["AD_mm_expected"], abs=0.01)
    assert rows[6].details[0]["dAP_mm"] == pytest.approx(truth["dAP_mm_expected"], abs=0.01)
    assert max(d["E_mm"] for d in rows[7].details) == pytest.approx(truth["E_mm_expected"], abs=0.012)


def test_simulated_path_characteristics(simulated):
    sim, rows = simulated
    truth, e = sim.truth, ERRORS
    for d in rows[8].details:
        r = np.array(truth[f"path_{d['path']}_lateral_random_mm"])
        dist = np.abs(r - r.mean())
        assert d["AT_mm"] == pytest.approx(1e3 * (e.path_offset + e.path_wave) + r.mean(), abs=0.005)
        # RT is a maximum over 200 commanded points: it picks up the tracker noise (1 µm per axis)
        assert d["RT_mm"] == pytest.approx(dist.mean() + 3 * dist.std(ddof=1), abs=0.01)
    assert rows[9].details[0]["AT_abc_deg"] == pytest.approx(truth["AT_abc_deg_expected"], abs=0.001)
    for d in rows[10].details:
        assert d["CR_mm"] == pytest.approx(truth["CR_mm_expected"], abs=0.025)
        assert d["CO_mm"] == pytest.approx(truth["CO_mm_expected"], abs=0.01)
    assert len(rows[10].details) == 3  # the rectangle's corners E2, E3, E4
    v = rows[11].details[0]
    assert v["AV_percent"] == pytest.approx(truth["AV_percent_expected"], abs=0.15)
    w = 2 * math.pi * e.speed_ripple_hz * 0.05 / 2
    fv = 2 * e.speed_ripple * truth["v_c_mm_s"] * math.sin(w) / w
    assert v["FV_mm_s"] == pytest.approx(fv, rel=0.1)
    for d in rows[14].details:
        assert d["WS_percent"] == pytest.approx(truth["WS_percent_expected"], abs=0.2)
        assert d["WF_percent"] == pytest.approx(truth["WF_percent_expected"], abs=0.05)


def test_simulated_positioning_and_compliance(simulated):
    sim, rows = simulated
    expected = sim.truth["positioning_time_s_expected"]
    assert len(rows[12].details) == len(expected)
    for d in rows[12].details:
        assert d["time_s"] == pytest.approx(expected[f"{d['distance_mm']:g}"], abs=2.0 / PLAN.rate_hz)
    comp = sim.truth["compliance_mm_per_N_expected"]
    for d in rows[13].details:
        assert d["compliance_mm_per_N"] == pytest.approx(comp[d["direction"]], rel=0.01)


def test_simulated_log_round_trip_and_command(simulated, tmp_path):
    sim, rows = simulated
    log = sim.log
    keep = np.isin(log.test, ["pose", "path", "compliance"])
    small = Iso9283Log(
        source="x",
        conditions={**log.conditions, "operator": "<script>alert(1)</script>"},
        time=log.time[keep],
        test=log.test[keep],
        cycle=log.cycle[keep],
        target=log.target[keep],
        group=log.group[keep],
        position=log.position[keep],
        commanded=log.commanded[keep],
        rotation=log.rotation[keep],
        commanded_rotation=log.commanded_rotation[keep],
        force=log.force[keep],
    )
    path = write_iso9283_log(small, tmp_path / "iso.csv")
    back = read_iso9283_log(path)
    assert back.n == small.n
    assert np.abs(back.position - small.position).max() < 1e-9
    assert np.abs(back.rotation - small.rotation).max() < 1e-7
    html_path = tmp_path / "iso.html"
    result = runner.invoke(app, ["iso9283", str(path), "--json", "-o", str(html_path)])
    assert result.exit_code == 0, result.output
    data = json.loads(result.output)
    got = {c["number"]: c for c in data["characteristics"]}
    assert got[1]["details"][0]["AP_mm"] == pytest.approx(rows[1].details[0]["AP_mm"], abs=1e-5)
    assert not got[2]["measured"] and "multidirectional" in got[2]["summary"]
    page = html_path.read_text()
    assert "<script>" not in page and "&lt;script&gt;" in page
    again = runner.invoke(app, ["iso9283", str(path), "-o", str(html_path)])
    assert again.exit_code == 2 and "--force" in again.output
    table = runner.invoke(app, ["iso9283", str(path), "--band", "0.05mm"])
    assert table.exit_code == 0 and "not measured" in table.output
    bad = runner.invoke(app, ["iso9283", str(path), "--band", "0.05"])
    assert bad.exit_code == 2 and "give the unit" in bad.output


def test_results_html_escapes_targets():
    log = _static_log({"<b>P1</b>": np.array([0.5, 0.0, 0.4])}, [np.zeros(3), np.full(3, 1e-5)])
    page = results_html(evaluate_log(log))
    assert "<b>P1" not in page and "&lt;b&gt;P1" in page


def test_the_documented_example_log_reads(tmp_path):
    from pathlib import Path

    doc = (Path(__file__).parents[1] / "docs" / "iso9283.md").read_text(encoding="utf-8")
    block = doc.split("Example (the start of a simulated log")[1].split("```")[1]
    log = read_iso9283_log(_write(tmp_path, block.lstrip("\n")))
    assert log.n == 3 and log.conditions["limit_band_mm"] == "0.1"
    assert log.position[0] == pytest.approx([-0.31864183, -0.995990399, -0.318476028])


def test_degenerate_logs_give_reasons_not_exceptions():
    """Every test present but each one unusable: straight weaves, stationary paths, a
    diagonal load, a single approach direction ... -> 14 rows, none measured, each with
    a reason."""
    rows = []
    t = 0.0
    for test in ("pose", "multidirectional", "distance", "drift", "exchangeability", "positioning"):
        for j in (1, 2):
            rows.append((t, test, j, "P1", "", [0.5, 0, 0.4], [0.5, 0, 0.4], [0, 0, 0]))
            t += 1
    for test in ("path", "reorientation", "cornering", "velocity", "weaving"):
        for j in (1, 2):
            for k in range(20):  # stationary, or a straight line without corners / weave
                x = 0.0 if test in ("path", "velocity") else 0.001 * k
                rows.append((t, test, j, "line", "", [x, 0, 0.4], [x, 0, 0.4], [0, 0, 0]))
                t += 0.01
    rows.append((t, "compliance", 1, "P1", "", [0.5, 0, 0.4], [0.5, 0, 0.4], [0, 0, 0]))
    rows.append((t + 1, "compliance", 1, "P1", "", [0.5, 0, 0.4], [0.5, 0, 0.4], [10.0, 10.0, 0]))
    n = len(rows)
    log = Iso9283Log(
        source="<degenerate>",
        conditions={},
        time=np.array([r[0] for r in rows]),
        test=np.array([r[1] for r in rows]),
        cycle=np.array([r[2] for r in rows]),
        target=np.array([r[3] for r in rows]),
        group=np.array([r[4] for r in rows]),
        position=np.array([r[5] for r in rows], dtype=float),
        commanded=np.array([r[6] for r in rows], dtype=float),
        force=np.array([r[7] for r in rows], dtype=float),
    )
    assert log.n == n
    res = evaluate_log(log)
    assert [r.number for r in res.rows] == list(range(1, 15))
    not_measured = [r for r in res.rows if not r.measured]
    assert all(r.summary.startswith("not measured: ") and len(r.summary) > 20 for r in not_measured)
    assert {r.number for r in not_measured} >= {2, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14}
    json.dumps(res.to_dict(), allow_nan=False)


def test_simulate_log_options(tmp_path):
    both = runner.invoke(
        app, ["simulate", "ur10", "--log", "-o", str(tmp_path / "a.csv"), "--poses", "p.csv"]
    )
    assert both.exit_code == 2 and "drop --poses" in both.output
    neither = runner.invoke(app, ["simulate", "ur10"])
    assert neither.exit_code == 2 and "--log" in neither.output
    assert not (tmp_path / "a.csv").exists()


@pytest.mark.slow
def test_simulate_log_command_end_to_end(tmp_path):
    """The README's two commands: every characteristic measured, the truth beside the log."""
    log = tmp_path / "iso.csv"
    made = runner.invoke(app, ["simulate", "ur10", "--log", "-o", str(log), "--seed", "1"])
    assert made.exit_code == 0, made.output
    assert (tmp_path / "iso.truth.yaml").is_file()
    result = runner.invoke(app, ["iso9283", str(log), "--json"])
    assert result.exit_code == 0, result.output
    assert all(c["measured"] for c in json.loads(result.output)["characteristics"])
    again = runner.invoke(app, ["simulate", "ur10", "--log", "-o", str(log)])
    assert again.exit_code == 2 and "--force" in again.output
