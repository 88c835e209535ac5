"""One calibration engine (issue 32 items 1, 2, 5): the single-robot staged path and the
batched engine run the same stage functions (a changed stage changes both alike), and the
decision rules (condition number, pruning thresholds) are defined in identify/rules.py only."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

import robocal as rc
from robocal.identify import fused, stages
from robocal.identify.batch import calibrate_batch
from robocal.identify.options import Pruning
from robocal.identify.rules import NO_CANDIDATE, Rules
from robocal.measure import LaserTracker, VirtualRobot, draw_true_model, simulate
from robocal.measure.poses import random_poses

TOOL = np.array([0.05, 0.0, 0.109])
TIGHT = Pruning(max_std=1e-7, max_std_ratio=1.3)  # prunes several unknowns after the fit
SRC = Path(rc.__file__).parent


def _data(seed: int, n: int = 30):
    model = rc.robot("ur10")
    device = LaserTracker(p_tool_target=TOOL, sigma=20e-6)
    robot = VirtualRobot(model, draw_true_model(model, seed=seed), device)
    return model, simulate(robot, random_poses(model, n, seed=seed + 1), seed=seed + 2)


class _Spy:
    """The stage kernels, with each stage rule's calls counted (and pruning optionally off)."""

    def __init__(self, kernels, prune: bool = True) -> None:
        self.kernels, self.prune, self.calls = kernels, prune, {"screen": 0, "prune": 0, "covariance": 0}

    def __getattr__(self, name):
        return getattr(self.kernels, name)

    def screen(self, *args):
        self.calls["screen"] += 1
        return self.kernels.screen(*args)

    def prune_candidate(self, *args):
        self.calls["prune"] += 1
        return self.kernels.prune_candidate(*args) if self.prune else NO_CANDIDATE

    def covariance(self, *args):
        self.calls["covariance"] += 1
        return self.kernels.covariance(*args)


def _both_paths(monkeypatch, prune: bool):
    """rc.calibrate's staged path and calibrate_batch on the same robot, with the stage
    kernels spied on; the calls each made."""
    model, data = _data(3)
    spy = _Spy(stages.stage_kernels(), prune)
    monkeypatch.setattr(stages, "stage_kernels", lambda: spy)
    monkeypatch.setattr(fused, "applies", lambda *args: False)  # the staged functions, not numba's fused fit
    single = rc.calibrate(model, data, tool_guess=TOOL, pruning=TIGHT)
    calls_single, spy.calls = dict(spy.calls), {k: 0 for k in spy.calls}
    (batched,) = calibrate_batch(model, [data], tool_guess=TOOL, rules=Rules.of(TIGHT))
    return single, batched, calls_single, dict(spy.calls)


def _decisions(fit):
    return tuple(fit.names), [(d.name, d.reason) for d in fit.dropped]


def test_single_and_batched_calibrations_run_the_same_stage_functions(monkeypatch):
    single, batched, calls_single, calls_batched = _both_paths(monkeypatch, prune=True)
    for stage in ("screen", "prune", "covariance"):
        assert calls_single[stage] > 0 and calls_batched[stage] > 0, (stage, calls_single, calls_batched)
    assert _decisions(batched) == _decisions(single)
    np.testing.assert_allclose(batched.estimates, single.estimates, rtol=1e-10, atol=1e-13)


def test_a_changed_stage_changes_both_engines_alike(monkeypatch):
    """Pruning switched off in the one stage function: neither engine prunes after its fit
    (a second orchestration with its own pruning would still prune)."""
    model, data = _data(3)
    reference = rc.calibrate(model, data, tool_guess=TOOL, pruning=TIGHT)
    single, batched, _, _ = _both_paths(monkeypatch, prune=False)
    assert _decisions(batched) == _decisions(single)
    assert len(single.names) > len(reference.names)  # the tight rules pruned some after the fit
    np.testing.assert_allclose(batched.estimates, single.estimates, rtol=1e-10, atol=1e-13)


def test_both_engines_order_their_stages_through_fit_selection(monkeypatch):
    """One place orders screening, the fit and pruning: both engines call
    ``stages.fit_selection``, and a changed order there reaches both."""
    from robocal.identify import batch, pipeline

    seen: list[str] = []

    def spy(stages_, selection):
        seen.append(type(stages_).__name__)
        return stages.fit_selection(stages_, selection)

    monkeypatch.setattr(pipeline, "fit_selection", spy)
    monkeypatch.setattr(batch, "fit_selection", spy)
    monkeypatch.setattr(fused, "applies", lambda *args: False)
    model, data = _data(3)
    rc.calibrate(model, data, tool_guess=TOOL, pruning=TIGHT)
    calibrate_batch(model, [data], tool_guess=TOOL, rules=Rules.of(TIGHT))
    assert seen == ["_Staged", "_BatchStages"]


_CONDITION = re.compile(r"np\.linalg\.cond\(|sqrt\(\s*\w+\[(-1|\w+ - 1)\]\s*/\s*\w+\[0\]\s*\)")
_THRESHOLD = re.compile(r"\b(max_std|max_std_ratio|screen_margin)\s*(:\s*float)?\s*=\s*[-+]?\.?\d")


def test_the_rules_are_defined_in_rules_py_only():
    """No module but identify/rules.py computes a condition number from eigenvalues or
    writes a default of a pruning or screening threshold as a number."""
    found = []
    for path in sorted(SRC.rglob("*.py")):
        if path == SRC / "identify" / "rules.py":
            continue
        for i, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            code = line.split("#", 1)[0]
            if _CONDITION.search(code) or _THRESHOLD.search(code):
                found.append(f"{path.relative_to(SRC)}:{i}: {line.strip()}")
    assert not found, "\n".join(found)
    # the patterns do find what they are for
    rules_text = (SRC / "identify" / "rules.py").read_text(encoding="utf-8")
    assert _CONDITION.search(rules_text) and _THRESHOLD.search(rules_text)


def test_streamed_covariance_reports_the_rules_condition_number():
    from robocal.identify.rules import condition_number
    from robocal.identify.streaming import NormalEquations, streamed_covariance

    rng = np.random.default_rng(2)
    J = rng.normal(size=(90, 5)) * np.logspace(0, 3, 5)
    r = rng.normal(size=90)
    ne = NormalEquations(J.T @ J, J.T @ r, float(r @ r), 90)
    Jn = J / np.linalg.norm(J, axis=0)
    cov = streamed_covariance(ne, False, Rules())
    assert cov.condition == pytest.approx(condition_number(np.linalg.eigvalsh(Jn.T @ Jn)), rel=1e-9)
    # the same fit through the dense stage function: the same covariance
    dense = stages.uncertainty(r, J, 3, False, Rules())
    np.testing.assert_allclose(cov.covariance, dense.covariance, rtol=1e-8, atol=1e-14)
    assert cov.condition == pytest.approx(dense.condition, rel=1e-8)
