"""Every module path the documentation names exists (issue 32 item 8: the docs follow the
restructure).

* Dotted paths ``robocal.x.y[.Name]`` in ``docs/**/*.md``, ``README.md`` and the latest
  section of ``CHANGELOG.md`` import: the longest module prefix is imported and the rest is
  looked up on it as attributes.
* File paths — ``src/robocal/...``, ``robocal/...``, a package-relative ``identify/...py``
  (relative to ``src/robocal``), ``tests/...``, ``benchmarks/...``, ``examples/...``,
  ``docs/...`` — exist.
* The changelog's "Removed" names do not import; in its "Moved" list (``old`` → ``new``,
  dotted module paths or files) the new one exists and the old one does not (or is now the
  package that holds the new one).
* ``docs/architecture.md``'s package tree: every file and folder drawn exists where the
  tree puts it, and every sub-package of ``src/robocal`` is drawn.
"""

from __future__ import annotations

import importlib
import importlib.util
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SRC = ROOT / "src"
PACKAGE = SRC / "robocal"
LAYER_PACKAGES = ("model", "measure", "identify", "compensate", "evaluate", "workflow", "study",
                  "cli", "apps", "demo", "experiments")  # fmt: skip

DOTTED = re.compile(r"(?<![\w./-])robocal(?:\.[A-Za-z_]\w*)+")
ROOTED = re.compile(r"(?<![\w./-])((?:src/robocal|robocal|tests|benchmarks|examples|docs)/[\w./-]*\w/?)")
RELATIVE = re.compile(rf"(?<![\w./-])((?:{'|'.join(LAYER_PACKAGES)})/[\w/]*\w(?:\.py|/))(?!\w)")
BARE_PY = re.compile(r"(?<![\w./-])(\w+\.py)\b")
MOVED_LINE = re.compile(r"`([^`]+)`\s*→\s*`([^`]+)`")


def changelog_latest() -> str:
    """The first ``## [...]`` section of CHANGELOG.md (the one being written)."""
    text = (ROOT / "CHANGELOG.md").read_text(encoding="utf-8")
    sections = re.split(r"^## \[", text, flags=re.MULTILINE)
    return "## [" + sections[1] if len(sections) > 1 else ""


def split_off(section: str, title: str) -> tuple[str, str]:
    """``(the section without its "### title" part, that part)``."""
    match = re.search(rf"^### {title}\n(.*?)(?=^### |\Z)", section, re.MULTILINE | re.DOTALL)
    if match is None:
        return section, ""
    return section[: match.start()] + section[match.end() :], match.group(1)


def changelog_parts() -> tuple[str, str, str]:
    """The latest section's text apart from "Moved" and "Removed", then those two (whose
    old paths must be gone)."""
    rest, moved = split_off(changelog_latest(), "Moved")
    rest, removed = split_off(rest, "Removed")
    return rest, moved, removed


def pages() -> dict[str, str]:
    """Page name -> text of every page whose paths are checked."""
    texts = {
        p.relative_to(ROOT).as_posix(): p.read_text(encoding="utf-8")
        for p in sorted((ROOT / "docs").rglob("*.md"))
    }
    texts["README.md"] = (ROOT / "README.md").read_text(encoding="utf-8")
    texts["CHANGELOG.md"] = changelog_parts()[0]
    return texts


def resolves(dotted: str) -> bool:
    """Whether ``dotted`` is a module of the package, or a name reachable from one."""
    parts = dotted.split(".")
    for n in range(len(parts), 0, -1):
        module_name = ".".join(parts[:n])
        try:
            if importlib.util.find_spec(module_name) is None:
                continue
        except ModuleNotFoundError:
            continue
        try:
            obj = importlib.import_module(module_name)
        except ImportError as error:  # an optional dependency (e.g. the GUI's dash) is absent
            if (error.name or "robocal").startswith("robocal"):
                raise
            return True  # the module's file exists (find_spec above); its names cannot be checked
        for attribute in parts[n:]:
            if not hasattr(obj, attribute):
                return False
            obj = getattr(obj, attribute)
        return True
    return False


def path_exists(path: str) -> bool:
    """Whether a documented file path exists (``*`` globs: at least one match)."""
    path = path.rstrip("/.")
    if path.startswith("robocal/"):
        path = "src/" + path
    elif path.split("/", 1)[0] in LAYER_PACKAGES:
        path = "src/robocal/" + path
    return any(ROOT.glob(path)) if "*" in path else (ROOT / path).exists()


def test_dotted_paths_import() -> None:
    found = {(name, m) for name, text in pages().items() for m in DOTTED.findall(text)}
    assert len(found) > 40  # the extraction finds the pages' paths (a broken pattern finds none)
    missing = sorted(f"{name}: {dotted}" for name, dotted in found if not resolves(dotted))
    assert not missing, "dotted paths that do not import:\n" + "\n".join(missing)


def test_file_paths_exist() -> None:
    found = set()
    for name, text in pages().items():
        found |= {(name, m) for m in ROOTED.findall(text)} | {(name, m) for m in RELATIVE.findall(text)}
    assert any(p.startswith("src/robocal/") for _, p in found) and len(found) > 60
    missing = sorted(f"{name}: {path}" for name, path in found if not path_exists(path))
    assert not missing, "paths that do not exist:\n" + "\n".join(missing)


def exists(path: str) -> bool:
    """A file path exists, or a dotted module path imports."""
    return path_exists(path) if "/" in path else resolves(path)


def test_changelog_lists_the_moves() -> None:
    _, moved_text, removed_text = changelog_parts()
    moved = MOVED_LINE.findall(moved_text)
    assert len(moved) >= 40  # the restructure moved 44 modules
    # an old module that became a package of the same name holds its new module
    gone = [(old, new) for old, new in moved if not exists(old) or new.startswith(old + ".")]
    wrong = [f"{old} → {new}" for old, new in moved if (old, new) not in gone or not exists(new)]
    assert not wrong, "moves whose old path exists or new path does not:\n" + "\n".join(wrong)
    removed = DOTTED.findall(removed_text)
    assert removed and not [name for name in removed if resolves(name)]


def package_tree() -> list[str]:
    """The lines of architecture.md's tree under ``src/robocal/`` (up to ``tests/``)."""
    text = (ROOT / "docs" / "architecture.md").read_text(encoding="utf-8")
    block = re.search(r"^```text\nsrc/robocal/\n(.*?)^```", text, re.MULTILINE | re.DOTALL)
    assert block, "docs/architecture.md has no ```text block starting with src/robocal/"
    lines = block.group(1).splitlines()
    return lines[: next(i for i, line in enumerate(lines) if not line.startswith(" "))]


def tree_entries(lines: list[str]) -> tuple[list[Path], list[Path]]:
    """(every path the tree draws, the folders among them).  An entry is a name ending in
    ``.py`` or ``/`` indented by two spaces per level; a ``name.py`` in its description (or
    the continuation lines below it) sits in the entry's folder."""
    drawn: list[Path] = []
    stack: list[Path] = [PACKAGE]
    here = PACKAGE
    for line in lines:
        indent = len(line) - len(line.lstrip(" "))
        token, _, rest = line.strip().partition(" ")
        if indent < 20 and re.fullmatch(r"[\w/]+/|\w+\.py", token):
            stack = stack[: indent // 2]
            entry = stack[-1] / token.rstrip("/")
            drawn.append(entry)
            if token.endswith("/"):
                stack.append(entry)
            here = entry if token.endswith("/") else entry.parent
        else:
            rest = line
        drawn += [here / name for name in BARE_PY.findall(rest)]
    return drawn, [p for p in drawn if p.suffix != ".py"]


def test_architecture_tree_matches_the_package() -> None:
    drawn, folders = tree_entries(package_tree())
    missing = sorted(str(p.relative_to(SRC)) for p in drawn if not p.exists())
    assert not missing, "drawn in docs/architecture.md's tree but absent:\n" + "\n".join(missing)
    shown = {p for f in folders for p in (f, *f.parents)}
    packages = {p.parent for p in PACKAGE.rglob("__init__.py") if p.parent != PACKAGE}
    absent = sorted(str(p.relative_to(SRC)) for p in packages - shown)
    assert not absent, "sub-packages missing from docs/architecture.md's tree:\n" + "\n".join(absent)


TREE_CASES = [
    (
        "  model/            step 1\n    chain.py          Model;  steps.py: parts",
        ["model", "model/chain.py", "model/steps.py"],
    ),
    (
        "  model/            x\n    urdf/             URDFs: read.py, export.py",
        ["model", "model/urdf", "model/urdf/read.py", "model/urdf/export.py"],
    ),
    (
        "  apps/gui/         GUI\n    app.py            the app\n  x.py              y",
        ["apps/gui", "apps/gui/app.py", "x.py"],
    ),
]


@pytest.mark.parametrize(("line", "expected"), TREE_CASES)
def test_the_tree_reader_places_names_in_their_folders(line: str, expected: list[str]) -> None:
    drawn, _ = tree_entries(line.splitlines())
    assert [p.relative_to(PACKAGE).as_posix() for p in drawn] == expected


def test_a_wrong_path_is_caught() -> None:
    """The checks fail where they should (a test of the test's own readers)."""
    assert not resolves("robocal.identify.residual_cv")  # moved to robocal.identify.residual.cv
    assert not resolves("robocal.identify.rules.NoSuchRule")
    assert resolves("robocal.identify.residual.cv") and resolves("robocal.identify.rules.Rules")
    assert not path_exists("src/robocal/measure/dataset.py") and path_exists("measure/dataset/read.py")
    assert RELATIVE.findall("see `identify/kernels/lm.py` and robocal/identify/x.py") == [
        "identify/kernels/lm.py"
    ]
