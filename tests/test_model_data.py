"""A model's compiled work arrays in an object the caller owns (``model.data()``, Pinocchio's
model / data), the derived-model fast path against the checked constructor, and the caches
that used to be keyed by ``id()``."""

from __future__ import annotations

import threading

import numpy as np
import pytest

import robocal as rc
from robocal.model.chain import Model
from robocal.model.chain_plan import derived_copy

pytest.importorskip("numba")

TOL = 1e-12


def _q(model: Model, n: int, seed: int) -> np.ndarray:
    lim = np.clip(model.joint_limits, -np.pi, np.pi)
    return np.random.default_rng(seed).uniform(lim[:, 0], lim[:, 1], (n, model.dof))


@pytest.mark.parametrize("name", ["ur10", "puma560"])
def test_fk_and_jacobian_into_data_equal_the_new_array_path(name):
    """``fk(q, data=d)`` and ``joint_jacobian(q, data=d)`` write into ``d.T`` / ``d.J``, return
    them, and equal the numpy reference; the next call overwrites them."""
    model = rc.robot(name)
    d = model.data()
    Q = _q(model, 5, 1)
    T_ref = model.fk(Q, compiled=False)
    J_ref = model.joint_jacobian(Q)
    for k, q in enumerate(Q):
        assert model.fk(q, data=d) is d.T
        np.testing.assert_allclose(d.T, T_ref[k], rtol=0, atol=TOL)
        assert model.joint_jacobian(q, data=d) is d.J
        np.testing.assert_allclose(d.J, J_ref[k], rtol=0, atol=TOL)
    # many configurations: a new array, the data untouched
    before = d.T.copy()
    T_many = model.fk(Q, data=d)
    assert not np.shares_memory(T_many, d.data)
    np.testing.assert_allclose(T_many, T_ref, rtol=0, atol=TOL)
    np.testing.assert_array_equal(d.T, before)


def test_data_of_another_model_is_refused():
    """Data made for one robot never gives another robot's frame: the fast path declines and
    the general path refuses by name; an equal model (another object) is accepted."""
    ur10, ur5 = rc.robot("ur10"), rc.robot("ur5")
    d = ur10.data()
    q = _q(ur5, 1, 2)[0]
    with pytest.raises(ValueError, match=r"ur5|ur10"):
        ur5.fk(q, data=d)
    with pytest.raises(ValueError, match=r"ur5|ur10"):
        ur5.joint_jacobian(q, data=d)
    twin = Model(**_fields(ur10))  # equal values, another object
    assert twin is not ur10 and twin == ur10
    assert twin.fk(q, data=d) is d.T
    np.testing.assert_allclose(d.T, ur10.fk(q, compiled=False), rtol=0, atol=TOL)


def test_bad_configuration_with_data_is_refused_by_name():
    """NaN or a wrong length through the data path: the general path's error, data unset."""
    model = rc.robot("ur10")
    d = model.data()
    d.T[:] = 7.0
    with pytest.raises(ValueError, match="NaN"):
        model.fk(np.array([0.0, 0.0, np.nan, 0.0, 0.0, 0.0]), data=d)
    with pytest.raises(ValueError, match="joints"):
        model.fk(np.zeros(5), data=d)
    assert np.all(d.T == 7.0)


def test_each_data_is_its_own():
    """Two ``data()`` share no buffer: two threads, each with its own, get their own frames."""
    model = rc.robot("ur10")
    Q = _q(model, 200, 3)
    want = model.fk(Q, compiled=False)
    results: dict[int, np.ndarray] = {}

    def work(k: int) -> None:
        d = model.data()
        out = np.empty((len(Q), 4, 4))
        for i in range(len(Q)):
            out[i] = model.fk(Q[(i + k) % len(Q)], data=d)
        results[k] = np.roll(out, k, axis=0)

    a, b = model.data(), model.data()
    assert not np.shares_memory(a.data, b.data)
    threads = [threading.Thread(target=work, args=(k,)) for k in (0, 7)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=120)
    for k in (0, 7):
        np.testing.assert_allclose(results[k], want, rtol=0, atol=TOL)


@pytest.mark.parametrize("same", ["free", "values"])
def test_derived_copy_is_the_checked_construction(same):
    """The solvers' fast path (:func:`derived_copy`, no ``__post_init__``) yields the model the
    checked constructor builds from the same steps: equal, same hash, same kinematics."""
    model = rc.robot("ur10")
    if same == "free":
        x = model.free_values + np.linspace(-1e-3, 1e-3, len(model.free_values))
        fast = model.with_free_values(x)
    else:
        fast = model.with_free(model.free_names[:3], free=False)
    checked = Model(
        name=fast.name,
        steps=fast.steps,
        bodies=fast.bodies,
        title=fast.title,
        source=fast.source,
        notes=fast.notes,
        joint_effects=fast.joint_effects,
        residual=fast.residual,
    )
    assert fast == checked and hash(fast) == hash(checked)
    assert fast.free_names == checked.free_names and fast.names == checked.names
    np.testing.assert_array_equal(fast.values, checked.values)
    np.testing.assert_array_equal(fast.free_mask, checked.free_mask)
    Q = _q(model, 4, 5)
    np.testing.assert_array_equal(fast.fk(Q), checked.fk(Q))
    np.testing.assert_array_equal(fast.jacobian(Q), checked.jacobian(Q))
    np.testing.assert_array_equal(fast.fk(Q[0]), checked.fk(Q[0]))
    # and with other changes (the calibration's assembly): the same as the checked path
    renamed = derived_copy(model, model.steps, (), notes="calibrated")
    assert renamed == Model(**{**_fields(model), "notes": "calibrated"})


def _fields(model: Model) -> dict:
    names = ("name", "steps", "bodies", "title", "source", "notes", "joint_effects", "residual")
    return {k: getattr(model, k) for k in names}


def test_measurement_chain_follows_the_robot_by_value():
    """The measurement-chain templates are cached by the robot's value, not its ``id()``: a
    robot with other link values (even one made after another was freed, which may reuse
    its id) gets its own values; an equal robot the same chain."""
    import gc

    from robocal.identify.problem import measurement_chain

    base = rc.robot("ur10")
    eye, tool = np.eye(4), np.eye(4)
    for k in range(5):  # new robots, each freed before the next: ids get reused
        name = base.free_names[k]
        robot = base.with_values({name: base.step(name).value + 0.01 * (k + 1)})
        chain = measurement_chain(robot, eye, tool, "position", False)
        assert chain.step(name).value == robot.step(name).value
        np.testing.assert_array_equal(chain.values[: len(robot.values)], robot.values)
        del robot, chain
        gc.collect()
    twin = Model(**_fields(base))
    a = measurement_chain(base, eye, tool, "position", False)
    b = measurement_chain(twin, eye, tool, "position", False)
    assert a == b


def test_no_cache_is_keyed_by_an_object_identity():
    """Issue 32: work caches live in objects the caller owns (``Model.data()``), not in
    module-level tables keyed by ``id()`` (an id is reused once its object is freed, and
    such a table keeps model parts alive). A key built from ``id(...)`` is a regression."""
    import re
    from pathlib import Path

    import robocal

    # a key made of id(...), or a module-level table (UPPER_CASE) indexed or read by one
    keyed = re.compile(r"(key\s*=\s*\(?\s*id\(|\b[A-Z_]+\[\s*\(?id\(|\b[A-Z_]+\.get\(\s*\(?id\()")
    src = Path(robocal.__file__).parent
    found = [
        f"{path.relative_to(src)}:{n}"
        for path in sorted(src.rglob("*.py"))
        for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1)
        if keyed.search(line)
    ]
    assert not found, f"caches keyed by id(): {found}"
