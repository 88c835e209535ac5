import math
import textwrap

import numpy as np
import pytest
import yaml

import robocal as rc
from robocal.model.files import load_model, model_from_dict, save_model
from robocal.model.yaml_files import ModelFileError


@pytest.mark.parametrize("name", rc.robots())
def test_catalog_models_round_trip_exactly(tmp_path, name):
    model = rc.robot(name)
    path = save_model(model, tmp_path / f"{name}.yaml")
    again = load_model(path)
    assert again == model
    # and a second save is byte-identical
    assert save_model(again, tmp_path / "b.yaml").read_text() == path.read_text()


def test_round_trip_is_exact_for_arbitrary_floats(tmp_path):
    model = rc.robot("ur10")
    rng = np.random.default_rng(0)
    x = model.free_values + rng.normal(scale=1e-3, size=len(model.free_values)) * np.pi
    model = model.with_free_values(x).fixed(["d1"])
    model = model.with_values({"a2": -0.61200000000000003, "alpha3": 1e-300})
    again = load_model(save_model(model, tmp_path / "m.yaml"))
    assert again == model
    np.testing.assert_array_equal(again.values, model.values)


def test_save_is_atomic_and_leaves_no_temporary_files(tmp_path):
    path = tmp_path / "sub" / "m.yaml"
    save_model(rc.robot("katana450"), path)
    assert [p.name for p in path.parent.iterdir()] == ["m.yaml"]
    assert path.read_text().startswith("# robocal model 'katana450'")


def write(tmp_path, text: str, name: str = "bad.yaml"):
    path = tmp_path / name
    path.write_text(textwrap.dedent(text))
    return path


GOOD = """\
    name: arm
    units: {length: mm, angle: deg}
    convention: dh
    links:
      - {theta: 0, d: 100, a: 0, alpha: 90, limits: [-170, 170]}
      - {theta: -90, d: 0, a: 400, alpha: 0, fixed: [alpha]}
    tool:
      - {motion: Tz, param: flange, value: 80}
"""


def test_units_are_converted_at_the_edge(tmp_path):
    model = load_model(write(tmp_path, GOOD, "good.yaml"))
    assert model.step("d1").value == pytest.approx(0.1)
    assert model.step("theta2").value == pytest.approx(-math.pi / 2)
    assert model.joints[0].limits == pytest.approx((-170 * math.pi / 180, 170 * math.pi / 180))
    assert model.joint_names == ("q1", "q2")
    assert not model.step("alpha2").free and model.step("a2").free
    assert model.step("flange").value == pytest.approx(0.08)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (
            "name: arm\nchain:\n  - {motion: Tw, param: a}\n",
            r"chain\[0\]\.motion: Input should be 'Tx'",
        ),
        ("name: arm\nchain:\n  - {motion: Tx, param: a, value: .nan}\n", r"chain\[0\]\.value"),
        (
            "name: arm\nchain:\n  - {motion: Tx, param: a, valeu: 1}\n",
            r"chain\[0\]\.valeu: Extra inputs are not permitted",
        ),
        (
            "name: arm\nchain:\n  - {motion: Tx, param: a, value: abc}\n",
            r"chain\[0\]\.value: .*\(got 'abc'\)",
        ),
        (
            "name: arm\nchain:\n  - {motion: Tx, param: a}\n  - {motion: Ty, param: a}\n",
            "parameter name 'a' is used twice",
        ),
        (
            "name: arm\nchain:\n  - {motion: Tx, param: a, limits: [0, 1]}\n",
            r"chain\[0\]: Value error, 'limits' given",
        ),
        (
            "name: arm\nunits: {length: inch}\nchain:\n  - {motion: Tx, param: a}\n",
            r"units\.length: Input should be 'm' or 'mm'",
        ),
        ("chain:\n  - {motion: Tx, param: a}\n", r"name: Field required"),
        ("name: arm\nlinks:\n  - {theta: 0}\n", "'links' needs 'convention"),
        ("name: arm\n", "no 'links' and no 'chain'"),
        (
            "name: arm\nconvention: dh\nlinks:\n  - {theta: 0, beta: 1}\n",
            "'beta' is not a DH parameter",
        ),
        (
            "name: arm\nconvention: dh\nlinks:\n  - {theta: 0, limits: [2, 1]}\n",
            r"limits .* lower <= upper",
        ),
        (
            "name: arm\nchain:\n  - {motion: Tx, param: a}\nbodies:\n  - {name: b, frame: zz, mass: 1}\n",
            "frame 'zz'",
        ),
        (
            "name: arm\nchain:\n  - {motion: Tx, param: a}\nbodies:\n  - {name: b, frame: a, mass: -1}\n",
            r"bodies\[0\]\.mass",
        ),
        ("- just\n- a list\n", "must be a mapping, got list"),
        ("name: arm\nchain: [\n", "line 3, column 1"),
        ("name: &n arm\ntitle: *n\nchain:\n  - {motion: Tx, param: a}\n", "aliases"),
        (
            "name: arm\nchain:\n  - !!python/object/apply:os.system ['echo hi']\n",
            "could not determine a constructor",
        ),
    ],
)
def test_bad_model_files_name_the_file_and_field(tmp_path, text, message):
    path = write(tmp_path, text)
    with pytest.raises(ModelFileError, match=message) as info:
        load_model(path)
    assert str(path) in str(info.value)


def test_missing_file_raises_file_not_found(tmp_path):
    with pytest.raises(FileNotFoundError):
        load_model(tmp_path / "none.yaml")


def test_model_from_dict_accepts_parsed_yaml():
    model = model_from_dict(yaml.safe_load(textwrap.dedent(GOOD)))
    assert model.dof == 2 and model.name == "arm"


def test_catalog_lookup_errors_suggest_names():
    with pytest.raises(KeyError, match="Did you mean ur10"):
        rc.robot("ur1O")
    assert set(rc.robots()) >= {"ur10", "katana450", "li2016_3dof"}
