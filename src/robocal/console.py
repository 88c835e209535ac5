"""Terminal output shared by the ``robocal`` commands: one console each for results
and errors, the one way a command stops on bad input, and the one path user text takes
to the terminal.

Text from data (file names, CSV headers and cells, model, joint and study names, option
values, messages that quote them) passes :func:`safe` before it is put into a line with
Rich markup: control characters (terminal escape sequences, backspace, bell ...) are shown
as ``\\x1b``-style escapes and Rich markup in it is escaped, so a name such as ``[/x]`` or
``[red]`` prints as written.  The consoles below also refuse to let any string crash or
reach the terminal raw: every string they render has its control characters made visible,
and a string whose markup does not parse is printed as plain text.

Any terminal encoding: :func:`tolerate_terminal_encoding` (called by the ``robocal`` entry
point) makes stdout and stderr write what their encoding cannot hold as ASCII instead of
raising: ``—`` as ``-``, ``σ`` as ``sigma``, ``²`` as ``2``, ``é`` as ``e``, an undecodable
byte of a file name as ``\\xNN``, anything else as ``?``.
"""

from __future__ import annotations

import codecs
import re
import sys
import unicodedata

import typer
from rich.console import Console
from rich.errors import MarkupError
from rich.markup import escape

__all__ = [
    "check_input",
    "console",
    "err_console",
    "fail",
    "input_problem",
    "plain",
    "refuse_overwrite",
    "safe",
    "tolerate_terminal_encoding",
    "warn",
]

#: C0 controls except tab and newline, DEL and the C1 controls (ESC starts terminal
#: escape sequences; CSI 0x9b does on some terminals)
_CONTROL = re.compile(r"[\x00-\x08\x0b-\x1f\x7f-\x9f]")


def _visible(match: re.Match[str]) -> str:
    return f"\\x{ord(match.group()):02x}"


def plain(text: object) -> str:
    """``text`` as a string with its control characters shown as ``\\xNN`` (no markup escaping)."""
    return _CONTROL.sub(_visible, str(text))


def safe(text: object) -> str:
    """``text`` ready to be put into a line with Rich markup: control characters made
    visible and markup escaped (``[/x]`` prints as ``[/x]``)."""
    return escape(plain(text))


#: ASCII for the characters robocal's own messages use that have no ASCII decomposition
_ASCII = {
    "—": "-", "–": "-", "−": "-", "‐": "-", "…": "...", "·": ".", "×": "x", "±": "+/-",
    "≤": "<=", "≥": ">=", "≈": "~", "≠": "!=", "→": "->", "←": "<-", "°": " deg", "µ": "u", "μ": "u",
    "∞": "inf", "√": "sqrt", "‖": "|", "∘": "o", "Σ": "sum", "“": '"', "”": '"', "‘": "'", "’": "'",
    "─": "-", "│": "|", "━": "-", "┃": "|", "•": "*", "✓": "ok", "✗": "x",
}  # fmt: skip


def _ascii(char: str) -> str:
    """One character as ASCII: the table above, a Greek letter's name (σ -> sigma), the
    character's compatibility decomposition without accents (é -> e, ² -> 2), a lone
    surrogate (an undecodable byte of a file name) as ``\\xNN``, else ``?``."""
    if char in _ASCII:
        return _ASCII[char]
    if "\udc80" <= char <= "\udcff":
        return f"\\x{ord(char) - 0xDC00:02x}"
    name = unicodedata.name(char, "")
    if name.startswith("GREEK") and " LETTER " in name:
        letter = name.rsplit(" ", 1)[-1].lower()
        return letter.capitalize() if " CAPITAL " in name else letter
    plain_ = unicodedata.normalize("NFKD", char).encode("ascii", "ignore").decode("ascii")
    return plain_ or "?"


def _transliterate(err: UnicodeError) -> tuple[str, int]:
    if not isinstance(err, UnicodeEncodeError):
        raise err
    return "".join(_ascii(c) for c in err.object[err.start : err.end]), err.end


codecs.register_error("robocal-ascii", _transliterate)


def tolerate_terminal_encoding() -> None:
    """Make stdout and stderr print on any encoding: what the encoding cannot hold is
    written as ASCII (:func:`_ascii`) instead of raising ``UnicodeEncodeError``
    (``PYTHONIOENCODING=ascii``, a latin-1 locale, a file name with undecodable bytes)."""
    for stream in (sys.stdout, sys.stderr):
        reconfigure = getattr(stream, "reconfigure", None)
        if reconfigure is not None:
            reconfigure(errors="robocal-ascii")


class _SafeConsole(Console):
    """A Rich console that never lets a string crash it or reach the terminal raw."""

    def render_str(self, text: str, **kwargs):
        text = plain(text)
        try:
            return super().render_str(text, **kwargs)
        except MarkupError:  # data with markup-like text in a line the caller did not escape
            return super().render_str(text, **(kwargs | {"markup": False}))


#: Markup is off by default: a line is printed as written unless the call asks for markup
#: (``markup=True``) and escapes the data it quotes with :func:`safe`.
console = _SafeConsole(markup=False)
_status = console.status


def _safe_status(status, *args, **kwargs):  # a spinner's text is always read as markup by Rich
    return _status(safe(status) if isinstance(status, str) else status, *args, **kwargs)


console.status = _safe_status  # type: ignore[method-assign]
err_console = _SafeConsole(stderr=True, soft_wrap=True, markup=False)  # never wrapped mid-word


def fail(message: str) -> typer.Exit:
    """Print ``error: message`` on stderr; ``raise fail(...)`` exits with status 2.

    ``message`` is printed as it is written (no markup: it quotes data)."""
    err_console.print("[bold red]error:[/] " + safe(message), highlight=False, markup=True)
    return typer.Exit(code=2)


def warn(message: str) -> None:
    """Print ``warning: message`` on stderr (``message`` printed as written, no markup)."""
    err_console.print("[yellow]warning:[/] " + safe(message), highlight=False, markup=True)


def input_problem(path, what: str = "file") -> str | None:
    """Why ``path`` cannot be read as an input ``what``, in one line naming it, or None.

    A FIFO, socket or device (``/dev/stdin``) is named as such, not as missing."""
    import os
    import stat

    try:
        mode = os.stat(path).st_mode
    except FileNotFoundError:
        return f"{path} does not exist"
    except PermissionError:
        return f"{path}: permission denied; check the file's permissions"
    except OSError as err:
        return f"{path}: {err.strerror or err}"
    if stat.S_ISDIR(mode):
        return f"{path} is a directory; give a {what}"
    if not stat.S_ISREG(mode):
        return (
            f"{path} is not a regular file (a pipe, socket or device such as /dev/stdin): the {what} must "
            "be a file; save it to one and give its path"
        )
    return None


def check_input(path, what: str = "file") -> None:
    """Stop (exit 2) with :func:`input_problem`'s line when ``path`` is no readable file."""
    problem = input_problem(path, what)
    if problem is not None:
        raise fail(problem)


def refuse_overwrite(path, force: bool, what: str = "file") -> None:
    """Stop (exit 2) when ``path`` already holds a result and ``--force`` was not given.

    A directory counts as a result when it is not empty.
    """
    from pathlib import Path

    path = Path(path)
    exists = path.is_file() or (path.is_dir() and any(path.iterdir()))
    if exists and not force:
        raise fail(f"{path} already exists; use --force to overwrite this {what}")
