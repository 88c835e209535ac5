"""Filter a robot program through the page's calibration: the upload (URScript, RAPID, KRL with
its ``.dat``), :func:`robocal.compensate.programs.filter_file.filter_program_file` (the function
``robocal filter`` runs, with the same measured-tool check), the per-target table and every
refused target by name.  A program with a refused target is not handed out unless the page is
told to (``robocal filter --partial``): its refused targets stay as written."""

from __future__ import annotations

import io
import tempfile
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from dash import Dash, Input, Output, State, dcc, html, no_update

from robocal.apps.gui.calibrate_views import decode_bytes
from robocal.apps.gui.jobs import public_text
from robocal.outdir import atomic_write_bytes

__all__ = ["ProgramUpload", "fieldset", "filter_upload", "register"]

#: the per-target table's columns as the page shows them (key of a table row, heading)
_COLUMNS = (
    ("name", "target"),
    ("status", "status"),
    ("error_before_mm", "before mm"),
    ("correction_mm", "correction mm"),
    ("configuration", "configuration"),
    ("reason", "reason"),
)


def fieldset() -> html.Fieldset:
    """The controls: the program upload and whether refused targets may stay as written."""
    return html.Fieldset(
        [
            html.Legend("filter a robot program (after a calibration)"),
            dcc.Upload(
                html.Button("filter a program (URScript .script, RAPID .mod, KRL .src + .dat)"),
                id="upload-program",
                multiple=True,
            ),
            dcc.Checklist(
                id="program-partial",
                options=[
                    {"label": "hand it out even with refused targets (left as written)", "value": "yes"}
                ],
                persistence=True,
                persistence_type="session",
            ),
            html.Div(id="program-view", className="message"),
            dcc.Download(id="program-download"),
        ]
    )


@dataclass(frozen=True)
class ProgramUpload:
    """The uploaded files of one program (``contents``: the browser's data URLs)."""

    names: tuple[str, ...]
    contents: tuple[str, ...]


def register(app: Dash, workdir: Path) -> None:
    """The filter's callback: the tab's run's saved result filters the uploaded program."""

    @app.callback(
        Output("program-download", "data"),
        Output("program-view", "children"),
        Input("upload-program", "contents"),
        State("upload-program", "filename"),
        State("program-partial", "value"),
        State("cal-run-id", "data"),
        prevent_initial_call=True,
    )
    def filter_program(contents, names, partial, run_id):
        if not contents:
            return no_update, no_update
        run = None if run_id is None else workdir / "runs" / run_id
        if run is None or not (run / "result.json").is_file():
            return no_update, html.Span("calibrate first (or open a finished run)", className="error")
        upload = ProgramUpload(tuple(names or ()), tuple(contents))
        return filter_upload(run, upload, bool(partial))


def filter_upload(run: Path, upload: ProgramUpload, partial: bool) -> tuple[Any, Any]:
    """Filter ``upload`` through the calibration saved in ``run``: ``(download or no_update,
    the page's view)``."""
    from robocal.compensate.programs.filter_file import filter_program_file, language_of
    from robocal.compensate.programs.syntax import ProgramError
    from robocal.identify.measured_tool import probe_for
    from robocal.identify.result import CalibrationResult

    with tempfile.TemporaryDirectory(prefix="robocal-gui-program-") as tmp:
        folder = Path(tmp)
        try:
            program = _save_upload(upload, folder / "in")
            result = CalibrationResult.load(run)
            out = folder / "out" / program.name
            out.parent.mkdir()
            filtered = filter_program_file(
                program, result, out, probe=probe_for(result, None, "the measured tool"), require_probe=True
            )
        except (ProgramError, ValueError) as err:
            message = public_text(str(err), folder)
            return no_update, html.Span(message, className="error", id="program-error")
        files = {p.name: p.read_bytes() for p in sorted(out.parent.iterdir())}
        problems = [public_text(p, folder) for p in filtered.problems]
        untouched = [
            f"{Path(u.file).name}: line {u.line}: {u.text} ({u.reason})" for u in filtered.unsupported
        ]
    refused = [r for r in filtered.table if r["status"] == "refused"]
    view = _view(program.name, language_of(program.name), filtered.table, refused, problems, untouched)
    if refused and not partial:
        line = (
            f"{len(refused)} of {len(filtered.table)} target(s) refused; nothing handed out (tick "
            "'hand it out even with refused targets' to get it with them left as written)"
        )
        return no_update, [html.Div(line, className="error", id="program-error"), *view]
    return _download(files), view


def _save_upload(upload: ProgramUpload, folder: Path) -> Path:
    """The uploaded files in ``folder``; the program to filter (a KRL ``.src`` before its ``.dat``)."""
    from robocal.compensate.programs.filter_file import language_of

    if not upload.names or len(upload.names) != len(upload.contents):
        raise ValueError("the upload could not be read")
    folder.mkdir()
    saved = []
    for name, contents in zip(upload.names, upload.contents, strict=True):
        plain = Path(name).name
        if not plain or plain in (".", ".."):
            raise ValueError(f"{name!r}: not a file name")
        atomic_write_bytes(folder / plain, decode_bytes(contents))
        saved.append(folder / plain)
    for path in saved:
        language_of(path)  # an unknown suffix: refused by name
    sources = [p for p in saved if p.suffix.lower() != ".dat" or len(saved) == 1]
    others = [p for p in sources if p.name != "$config.dat"]
    if len(others) != 1:
        raise ValueError("upload one program (KRL: its .src with its .dat and $config.dat)")
    return others[0]


def _download(files: dict[str, bytes]) -> dict[str, Any]:
    """One file as it is; a KRL pair (``.src`` and ``.dat``) as one zip."""
    if len(files) == 1:
        ((name, data),) = files.items()
        return dcc.send_bytes(data, name)
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED) as archive:
        for name, data in files.items():
            archive.writestr(name, data)
    stem = Path(next(iter(files))).stem
    return dcc.send_bytes(buffer.getvalue(), f"{stem}_filtered.zip")


def _cell(value: Any) -> str:
    if value is None:
        return "-"
    return f"{value:.4f}" if isinstance(value, float) else str(value)


def _view(
    name: str,
    language: str,
    rows: tuple[dict, ...],
    refused: list[dict],
    problems: list[str],
    untouched: list[str],
) -> list[Any]:
    """The summary, the refused targets by name, the untouched statements and the table."""
    counts = {s: sum(r["status"] == s for r in rows) for s in ("corrected", "damped", "refused")}
    summary = f"{name} ({language}): {len(rows)} targets, " + ", ".join(f"{n} {s}" for s, n in counts.items())
    head = html.Tr([html.Th(h) for _, h in _COLUMNS])
    body = [
        html.Tr([html.Td(_cell(r.get(k)), className="num" if k.endswith("_mm") else "") for k, _ in _COLUMNS])
        for r in rows[:200]
    ]
    return [
        html.Div(summary, className="ok" if not refused else "warning", id="program-summary"),
        html.Ul([html.Li(f"refused: {r['name']}: {r['reason']}") for r in refused], id="program-refused"),
        html.Ul([html.Li(f"warning: {p}", className="warning") for p in problems if p]),
        html.Ul([html.Li(f"untouched: {u}") for u in untouched], id="program-untouched"),
        html.Table([html.Thead(head), html.Tbody(body)], id="program-table"),
    ]
