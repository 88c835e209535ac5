"""Robot programs filtered through a calibration, in their own language.

:func:`filter_program_text` / :func:`filter_program_file` read a robot program, correct
every target through the calibration and write the same program with the corrected
numbers and nothing else changed: every other byte (comments, formatting, other
statements, the numbers of targets that need no correction) is kept.  A program filtered
with a nominal calibration (calibrated = nominal) is byte-identical to its input.

Corrections (:mod:`robocal.compensate.compensation`):

* a **joint target** ``q`` becomes the joint values that put the real (calibrated) tool
  where the nominal model puts it at ``q`` (:func:`~robocal.compensate.compensation.filter_program`);
* a **Cartesian target** ``P`` becomes ``P' = nominal.fk(q')`` with ``q'`` the joint
  values at which the real robot reaches ``P`` (:func:`~robocal.compensate.compensation.compensate`):
  the controller, commanded ``P'``, solves its nominal IK to ``q'`` and the real robot
  lands on ``P``.  The IK branch is that of the configuration the robot comes from:
  the previous target in execution order (motions to named targets count where they
  run, e.g. a KRL ``.src`` ``LIN XP1`` and not its ``.dat`` declaration).

The robot is the calibrated model without the measured tool (``tcp_*``) — but with
how far the identified tool is from the probe as built (``probe``; robot geometry the
tool absorbed, e.g. ``d6`` under position measurement) —; the program's tool
(``set_tcp`` in URScript, a RAPID ``tooldata`` of the module, else ``tool`` given) is
appended as a fixed frame, and targets are taken in the robot's
base frame (``base`` given: ``T_base_frame`` of a KUKA BASE or a RAPID work object).
Without ``tool``/``base`` each Cartesian target takes those of the first motion to it:
a RAPID Move's ``tooldata`` and ``\\WObj`` declared in the module, KRL ``$TOOL``/``$BASE``
(``TOOL_DATA[n]``/``BASE_DATA[n]``, or an ``FDAT``'s ``TOOL_NO``/``BASE_NO``) from the
``$config.dat`` given.

Supported grammar (anything else is left untouched; motion statements outside it are
listed in :attr:`FilteredProgram.unsupported`):

* **URScript** (``.script``, ``.urscript``; m, rad): ``movej/movel/movep/movec/servoj``
  calls whose targets are literals ``p[x, y, z, rx, ry, rz]`` (rotation vector) or joint
  lists ``[q1, ..., qN]``, or names assigned such literals (``name = p[...]``,
  ``global name = [...]``); ``set_tcp(p[...])`` sets the tool.
* **KUKA KRL** (``.src`` and the ``.dat`` of the same name; mm, degrees): aggregates
  ``{X .., Y .., Z .., A .., B .., C .. [, S .., T .., E1 ..]}`` of ``DECL E6POS|POS``
  declarations and of ``PTP/LIN/CIRC`` statements (Cartesian; ``A, B, C`` =
  ``Rz(A) Ry(B) Rx(C)``), ``{A1 .., ..., A6 .. [, E1 ..]}`` of ``DECL E6AXIS|AXIS``
  and ``PTP`` (joint).  ``FRAME`` declarations (bases, tools) are data, not targets.
  Status/turn (``S``, ``T``) and external axes are kept as written and met by the
  correction (:func:`_status_bits`; a target reachable only in another configuration
  is reported and left as written).
* **ABB RAPID** (``.mod``, ``.modx``, ``.prg``; mm, degrees): ``robtarget`` literals
  ``[[x,y,z],[q1,q2,q3,q4],[cf1,cf4,cf6,cfx],[eax..]]`` (quaternion scalar first) in
  declarations and in ``MoveJ/MoveL/MoveC`` statements, ``jointtarget`` literals
  ``[[j1..j6],[eax..]]`` in declarations and ``MoveAbsJ``; ``cf1, cf4, cf6, cfx`` kept
  and met by the correction (:func:`_cfx_bits`).
* **robocal target CSV** (``.csv``): ``name,x,y,z[,qw,qx,qy,qz]`` (Cartesian, in
  ``length_unit``) or ``[name,]q1..qN`` (joint, in ``angle_unit``); ``#`` lines kept.

Only code is read: comments and strings are masked first (:func:`code_only`; URScript
``#``, KRL ``;``, RAPID ``!`` and double-quoted strings), so a ``movej([...])`` in a
comment or a ``textmsg``/``TPWrite`` string is kept byte for byte.  Every motion is either
corrected or listed in :attr:`FilteredProgram.unsupported` with its reason: arrays
(``path{1}``, ``XP[1]``), names the program gives no value (another module, set at run
time), offsets and computed targets (``Offs``, ``RelTool``, ``pose_trans``), relative and
other motion instructions (``LIN_REL``, ``MoveLDO``), and run-time changes of a target
(``p1.trans.z := ...``, ``p1 = pose_add(...)``).

A ``nominal`` model that is not the calibrated robot (other joint count, names or types,
or a flange more than :data:`~robocal.compensate.programs.frames.NOMINAL_AGREEMENT_M` from
the calibration's start model) is refused.  KRL pairs are read and written as pairs (see
:func:`filter_program_file`).  Files above :data:`MAX_PROGRAM_BYTES` (20 MB) are refused
before they are read; parsing and rewriting are linear in the size of the program.

Units: SI inside; each language's units in its file.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

import robocal.compensate.programs.steps as steps

# the names marked F401 below (parsers, units, configuration rules) are re-exported for the tests
from robocal.compensate.programs.frames import check_nominal, robot_models
from robocal.compensate.programs.krl import (
    check_krl_pair,
    krl_inputs,
    krl_module_name,
    krl_outputs,
    krl_run_id,
    stamp_krl,
)
from robocal.compensate.programs.syntax import (
    MAX_PROGRAM_BYTES,
    FilteredProgram,
    Language,
    ProgramError,
    ProgramTarget,
    Unsupported,
    code_only,
)
from robocal.compensate.programs.values import (
    read_value,
)
from robocal.identify.result import CalibrationResult
from robocal.model.chain import Model

__all__ = [
    "MAX_PROGRAM_BYTES",
    "FilteredProgram",
    "ProgramError",
    "ProgramTarget",
    "Unsupported",
    "code_only",
    "filter_program_file",
    "filter_program_text",
    "krl_module_name",
    "krl_run_id",
    "language_of",
    "stamp_krl",
]


# ---------------------------------------------------------------------- the filter
def language_of(path: str | Path) -> Language:
    """The language of a program file by its suffix."""
    suffix = Path(path).suffix.lower()
    table: dict[str, Language] = {
        ".script": "urscript",
        ".urscript": "urscript",
        ".src": "krl",
        ".dat": "krl",
        ".mod": "rapid",
        ".modx": "rapid",
        ".prg": "rapid",
        ".csv": "csv",
    }
    if suffix not in table:
        raise ProgramError(f"{path}: unknown program language {suffix!r} (.script, .src, .mod, .csv)")
    return table[suffix]


def filter_program_text(  # noqa: PLR0913 - public API: the filter's keyword options, unchanged
    texts: dict[str, str],
    language: Language,
    calibrated: CalibrationResult | Model,
    nominal: Model | None = None,
    *,
    tool: ArrayLike | None = None,
    base: ArrayLike | None = None,
    probe: ArrayLike | None = None,
    length_unit: str = "m",
    angle_unit: str = "rad",
    tol: float = 1e-9,
    config_dat: tuple[str, str] | None = None,
    require_probe: bool = False,
) -> FilteredProgram:
    """Filter a program given as texts ``{file label: text}`` (KRL: the ``.src`` and the
    ``.dat``; other languages one file).

    Args:
        calibrated: a calibration result or a calibrated model (with ``nominal``).
        nominal: the controller's model (default: the result's start values).
        tool: ``(4, 4)`` the program's tool frame on the flange (m); default the
            program's own (``set_tcp``, a ``tooldata``) or the flange.
        base: ``(4, 4)`` ``T_base_frame`` of the frame the Cartesian targets are in
            (KUKA BASE, RAPID work object); default the robot's base frame.
        probe: the calibration's measured tool as built (position ``(3,)`` or ``(4, 4)``
            on the flange, m): the identified tool's distance from it is robot geometry
            the tool absorbed (e.g. ``d6`` under position measurement) and is kept with
            the robot.  Default: the identified tool is the probe as built (nothing
            absorbed; right when the program's tool is the probe itself).
        length_unit, angle_unit: units of a CSV program (``m|mm``, ``rad|deg``).
        config_dat: KRL ``(label, text)`` of the ``$config.dat`` whose ``TOOL_DATA[n]`` and
            ``BASE_DATA[n]`` the program's ``$TOOL``/``$BASE`` (or ``FDAT`` ``TOOL_NO``,
            ``BASE_NO``) name; without it those are not read.  RAPID: each Move's tool
            and ``\\WObj`` (``uframe · oframe``) are read from the module.  Each Cartesian
            target is taken with the tool and base of the first motion to it; ``tool`` /
            ``base`` given override them all.
        require_probe: refuse (:class:`ProgramError`) a calibration that measured
            positions only, without ``probe``, when the program has Cartesian targets (the
            identified tool absorbed robot geometry, e.g. ``d6``; about 2 mm can be lost).
        tol: IK tolerance (m, rad); corrections smaller than it leave the text as is.
    """
    model = calibrated.model if isinstance(calibrated, CalibrationResult) else calibrated
    if nominal is not None:
        check_nominal(calibrated, nominal)
    parsed = steps.parse_program(texts, language, model.dof)
    targets = parsed.targets
    if require_probe:
        steps.check_probe(targets, calibrated, probe)
    units = steps.program_units(language, length_unit, angle_unit)
    effects = robot_models(calibrated, nominal, None, probe)[2]
    problems: list[str] = []
    frames_of = steps.frames_of_targets(
        parsed.code, language, parsed, calibrated, nominal, tool, base, probe, config_dat, problems
    )
    values = [read_value(t, units, model.joint_types, False) for t in targets]
    c = steps._Corrections.start(values, problems)
    joint_idx = [i for i, t in enumerate(targets) if t.kind == "joint"]
    steps.correct_joint_targets(values, joint_idx, frames_of, effects, tol, c)
    if any(t.kind == "pose" for t in targets):
        q_start = values[joint_idx[0]] if joint_idx else np.zeros(model.dof)
        sequence = steps.execution_order(texts, parsed)
        steps.correct_pose_targets(sequence, targets, values, q_start, frames_of, effects, tol, c)
    out, changed = steps.rewrite_texts(texts, targets, units, model.joint_types, c)
    _report(calibrated, targets, c)
    return FilteredProgram(
        texts=out,
        targets=tuple(targets),
        error_before_mm=c.before,
        error_after_mm=c.after,
        reachable=c.reach,
        branch_kept=c.kept,
        changed=changed,
        unsupported=tuple(parsed.unsupported),
        language=language,
        problems=tuple(c.problems),
        status=tuple(c.status),
        reasons=tuple(c.reasons),
        table=steps.target_table(targets, c),
    )


def _report(calibrated, targets: list, c) -> None:
    """The refused targets, and those whose commands need joint values no calibration pose
    came near (:func:`robocal.identify.coverage.coverage_warnings`), as problems."""
    from robocal.identify.coverage import coverage_warnings

    steps.report_refused(targets, c)
    done = [i for i, q in enumerate(c.joints) if q is not None]
    names = [f"{targets[i].file}: line {targets[i].line} {targets[i].name}" for i in done]
    if done:
        c.problems.extend(coverage_warnings(calibrated, np.array([c.joints[i] for i in done]), names))


def _read(path: Path) -> tuple[str, str]:
    """The text and its encoding (UTF-8, else Latin-1 as KRL and RAPID files often are);
    a file above :data:`MAX_PROGRAM_BYTES` is refused before it is read."""
    try:
        size = path.stat().st_size
        if size > MAX_PROGRAM_BYTES:
            raise ProgramError(
                f"{path}: {size / 1e6:.1f} MB; robot programs are read up to {MAX_PROGRAM_BYTES / 1e6:g} MB"
            )
        data = path.read_bytes()
    except OSError as err:
        raise ProgramError(f"{path}: cannot read: {err.strerror or err}") from None
    try:
        return data.decode("utf-8"), "utf-8"
    except UnicodeDecodeError:
        return data.decode("latin-1"), "latin-1"


def filter_program_file(
    path: str | Path,
    calibrated: CalibrationResult | Model,
    out: str | Path | None = None,
    *,
    language: Language | None = None,
    config_dat: str | Path | None = None,
    overwrite: bool = True,
    **options,
) -> FilteredProgram:
    """Filter a program file (see :func:`filter_program_text`); written to ``out``
    atomically when given (KRL: ``out`` and the ``.dat`` next to it, both or neither).  Nothing is
    written when the program cannot be read.

    KRL: a ``.src`` is read and written with its ``.dat`` (same name; ``DEF`` and ``DEFDAT``
    must name the same module) as a pair stamped with one run id; ``out`` must be a ``.src``
    too, and an existing ``.dat`` beside ``out`` that the program has none for is refused
    (it would be read with the new ``.src``).  A ``.dat`` is filtered alone only when no
    ``.src`` of its name is beside it.  ``overwrite=False`` refuses any existing output file.
    ``config_dat`` is the ``$config.dat`` holding ``TOOL_DATA``/``BASE_DATA`` (default: the
    one in the program's folder, when there is one)."""
    path = Path(path)
    if not path.is_file():
        raise ProgramError(f"{path}: no such program file")
    language = language or language_of(path)
    texts, encodings = {}, {}
    texts[str(path)], encodings[str(path)] = _read(path)
    if language == "krl":
        dat = krl_inputs(path, out)
        if dat is not None:
            texts[str(dat)], encodings[str(dat)] = _read(dat)
            check_krl_pair(path, texts[str(path)], dat, texts[str(dat)])
        cfg = Path(config_dat) if config_dat is not None else path.parent / "$config.dat"
        if config_dat is not None and not cfg.is_file():
            raise ProgramError(f"{cfg}: no such $config.dat")
        if cfg.is_file():
            options["config_dat"] = (str(cfg), _read(cfg)[0])
    targets = None if out is None else _output_files(path, Path(out), list(texts), language, overwrite)
    result = filter_program_text(texts, language, calibrated, **options)
    if targets is not None:
        from robocal.outdir import write_together
        from robocal.run_ids import new_run_id

        files = {}
        run_id = new_run_id()
        for label, text in result.texts.items():
            if language == "krl":  # the pair carries one run id: a mix is refused when read
                text = stamp_krl(text, run_id)
            files[targets[label]] = text.encode(encodings[label])
        # KRL: the .src and its .dat both or neither; the .dat renamed first, so that a
        # process killed in between leaves no new .src without its .dat
        write_together(dict(sorted(files.items(), key=lambda item: item[0].suffix.lower() != ".dat")))
    return result


def _output_files(
    path: Path, out: Path, labels: list[str], language: Language, overwrite: bool
) -> dict[str, Path]:
    """``{file label: output path}``; with ``overwrite=False`` an existing one is refused."""
    targets = krl_outputs(path, out, labels, overwrite) if language == "krl" else {str(path): out}
    existing = [p for p in targets.values() if p.exists()]
    if existing and not overwrite:
        raise ProgramError(f"{existing[0]} already exists; use --force to overwrite it")
    return targets
