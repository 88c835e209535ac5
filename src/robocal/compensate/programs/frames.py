"""The robot models a program runs on (its tool, the absorbed probe) and the tool and base
frames in force at each motion."""

from __future__ import annotations

import dataclasses
from bisect import bisect_right
from collections.abc import Callable

import numpy as np
from numpy.typing import ArrayLike

from robocal import spatial
from robocal.compensate.flanks import command_effects
from robocal.compensate.programs.krl import (
    krl_config_frames,
    krl_settings,
)
from robocal.compensate.programs.syntax import (
    Array,
    ProgramError,
    ProgramTarget,
    code_only,
    line_of,
)
from robocal.identify.problem import frame_steps
from robocal.identify.result import CalibrationResult
from robocal.model.chain import Model
from robocal.model.flange_tool import split_tool


def robot_models(
    calibrated: CalibrationResult | Model, nominal: Model | None, tool: Array | None, probe: ArrayLike | None
) -> tuple[Model, Model, Callable[[Array], Array | None] | None]:
    """(real, nominal) robot models with the program's tool, and the joint effects (a bare
    model's own too: they were left out, so its commands ignored the effects it states)."""
    from robocal.compensate.compensation import model_perturbations, nominal_model

    if isinstance(calibrated, CalibrationResult):
        real = calibrated.model
        nom = nominal_model(calibrated) if nominal is None else nominal
        effects = command_effects(calibrated)
    else:
        real, nom = calibrated, (calibrated if nominal is None else nominal)
        effects = model_perturbations(calibrated)

    # the measured tool as built (``probe``) is known: how far the identified tool is from it
    # is robot geometry the tool absorbed (e.g. d6 under position measurement), kept with the robot
    tool_real = split_tool(real).T_flange_tool
    absorbed = np.eye(4)
    if tool_real is not None and probe is not None:
        P = np.asarray(probe, dtype=float)
        absorbed = tool_real @ spatial.inverse(P if P.shape == (4, 4) else spatial.homogeneous(p=P))

    def strip(m: Model, correction: Array) -> Model:
        steps = split_tool(m).robot.steps
        T = correction @ (np.eye(4) if tool is None else np.asarray(tool, dtype=float))
        if np.abs(T - np.eye(4)).max() > 0:
            steps = (*steps, *frame_steps(T, "program_tool", free=False))
        return dataclasses.replace(m, steps=steps, joint_effects=())

    return strip(real, absorbed), strip(nom, np.eye(4)), effects


def program_frames(
    texts: dict[str, str],
    language: str,
    rapid_data: dict[str, dict],
    config_dat: tuple[str, str] | None,
    problems: list[str],
) -> Callable[[str, int], tuple[Array | None, Array | None]]:
    """``frame_at(file, position)``: the program's tool and base frames (m) in force at a
    motion (``None``: not given by the program)."""
    if language == "rapid":
        tools = {k: v for d in rapid_data.values() for k, v in d["tools"].items()}
        wobjs = {k: v for d in rapid_data.values() for k, v in d["wobjs"].items()}
        tools.setdefault("TOOL0", np.eye(4))
        wobjs.setdefault("WOBJ0", np.eye(4))
        seen: set[str] = set()

        starts = {label: [move[0] for move in d["moves"]] for label, d in rapid_data.items()}

        def rapid_at(label: str, pos: int) -> tuple[Array | None, Array | None]:
            k = bisect_right(starts[label], pos) - 1  # the Move statement holding pos (in file order)
            for start, end, line, tool, wobj in rapid_data[label]["moves"][max(k, 0) : k + 1]:
                if start <= pos < end:
                    for name, table, what in ((tool, tools, "tooldata"), (wobj, wobjs, "wobjdata")):
                        if name is not None and name.upper() not in table and name.upper() not in seen:
                            seen.add(name.upper())
                            problems.append(
                                f"{label}: line {line}: {what} {name} is declared outside the module; "
                                "the default is used (--tool / --base)"
                            )
                    return tools.get((tool or "TOOL0").upper()), wobjs.get((wobj or "WOBJ0").upper())
            return None, None

        return rapid_at
    if language != "krl" or config_dat is None:
        return lambda label, pos: (None, None)
    cfg_label, cfg_text = config_dat
    data = krl_config_frames(code_only(cfg_text, "krl"), cfg_label)  # commented-out frames are not read
    settings = krl_settings(texts)

    def krl_at(label: str, pos: int) -> tuple[Array | None, Array | None]:
        current: dict[str, Array | None] = {"TOOL": None, "BASE": None}
        for start, line, kind, n in settings.get(label, []):
            if start >= pos:
                break
            if n == 0:
                current[kind] = np.eye(4)
            elif (kind, n) in data:
                current[kind] = data[(kind, n)]
            else:
                raise ProgramError(f"{label}: line {line}: {kind}_DATA[{n}] is not in {cfg_label}")
        return current["TOOL"], current["BASE"]

    return krl_at


def report_other_frames(
    t: ProgramTarget,
    runs: list[tuple[str, int]],
    first: tuple[Array | None, Array | None],
    frame_at: Callable[[str, int], tuple[Array | None, Array | None]],
    texts: dict[str, str],
    problems: list[str],
) -> None:
    """A problem when motions to target ``t`` run with other tools or bases than the first."""

    def same(a: Array | None, b: Array | None) -> bool:
        return (a is None and b is None) or (a is not None and b is not None and np.allclose(a, b))

    lines = [
        f"{label}: line {line_of(texts[label], pos)}"
        for label, pos in runs[1:]
        if not all(same(x, y) for x, y in zip(frame_at(label, pos), first, strict=True))
    ]
    message = (
        f"{t.file}: line {t.line}: target {t.name}: moved to with another tool or base at "
        f"{', '.join(lines)}; corrected for the first motion to it"
    )
    if lines and message not in problems:
        problems.append(message)


#: a ``nominal`` model whose flange is farther than this (m) from the calibration's start
#: model's, at some joint values, is another robot: its targets would move by that much
NOMINAL_AGREEMENT_M = 0.05


def check_nominal(calibrated: CalibrationResult | Model, nominal: Model) -> None:
    """Refuse (:class:`ProgramError`) a controller model that is not the calibrated robot:
    other joints (count, names, types) or a flange more than :data:`NOMINAL_AGREEMENT_M`
    from the calibration's start model (a result) or the calibrated model (a model) at 64
    joint configurations within the limits; tools are left out of the comparison."""
    from robocal.compensate.compensation import nominal_model

    ref = nominal_model(calibrated) if isinstance(calibrated, CalibrationResult) else calibrated
    what = f"the nominal model {nominal.name!r} is not the calibration's robot {ref.name!r}"
    for label, a, b in (
        ("joints", ref.dof, nominal.dof),
        ("joint names", ", ".join(ref.joint_names), ", ".join(nominal.joint_names)),
        ("joint types", ", ".join(ref.joint_types), ", ".join(nominal.joint_types)),
    ):
        if a != b:
            raise ProgramError(f"{what}: {label} {b} (the calibration's: {a})")
    lim = ref.joint_limits
    lo, hi = np.maximum(lim[:, 0], -np.pi), np.minimum(lim[:, 1], np.pi)
    q = np.random.default_rng(0).uniform(lo, hi, (64, ref.dof))

    def flange(m: Model) -> Array:
        return split_tool(m).robot.fk(q)[:, :3, 3]

    gap = float(np.max(np.linalg.norm(flange(ref) - flange(nominal), axis=1)))
    if not gap <= NOMINAL_AGREEMENT_M:  # NaN too
        raise ProgramError(
            f"{what}: its flange is {gap * 1e3:.0f} mm from the calibration's at the same joint values "
            f"(at most {NOMINAL_AGREEMENT_M * 1e3:g} mm)"
        )
