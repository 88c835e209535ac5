"""YAML files read defensively (models, joint geometry, studies): a regular file of at
most :data:`MAX_FILE_BYTES`, UTF-8, no aliases, no repeated keys, bounded nesting and
entries — all checked before a document is built — and one message naming the file, line
and column when it cannot be read (:func:`read_yaml`)."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import yaml

__all__ = ["MAX_FILE_BYTES", "MAX_YAML_DEPTH", "MAX_YAML_EVENTS", "ModelFileError", "read_yaml"]

#: the largest YAML file read (bytes)
MAX_FILE_BYTES = 5_000_000


class ModelFileError(ValueError):
    """A model file could not be read; the message names the file and the field."""


class _DuplicateKeyCheck:
    """Refuses a key that appears twice in a mapping (mixed into the loaders below)."""

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict[Any, Any]:
        # YAML lets a later key silently replace an earlier one: a typo'd copy-paste would
        # then change a model without a word, so a repeated key is an error here
        seen: dict[Any, Any] = {}
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=True)  # type: ignore[attr-defined]
            try:
                first = seen.setdefault(key, key_node.start_mark)
            except TypeError:  # an unhashable key: the base class reports it
                continue
            if first is not key_node.start_mark:
                raise yaml.constructor.ConstructorError(
                    None,
                    None,
                    f"key {key!r} appears twice (first on line {first.line + 1})",
                    key_node.start_mark,
                )
        return super().construct_mapping(node, deep=deep)  # type: ignore[misc]


#: libyaml's parser where PyYAML has it (4x faster; the events are checked first, below)
_FastBase = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


class _FastLoader(_DuplicateKeyCheck, _FastBase):  # type: ignore[misc, valid-type]
    """libyaml's safe loader with the duplicate-key check; aliases, nesting and size are
    checked on the event stream before it runs (:func:`_check_events`)."""


#: YAML events (scalars, mapping and sequence starts ...) a file may have: a 1000-step
#: model has about 15 000; 200 000 take about 3 s to load
MAX_YAML_EVENTS = 200_000
#: Nesting depth a file may have (a model file has 4 levels)
MAX_YAML_DEPTH = 50


def _check_events(text: str) -> None:
    """Refuse aliases, nesting deeper than MAX_YAML_DEPTH and more than MAX_YAML_EVENTS
    events, in one linear pass of libyaml's parser (no document is built)."""
    depth = 0
    for count, event in enumerate(yaml.parse(text, Loader=_FastBase), start=1):
        if isinstance(event, yaml.AliasEvent):
            raise yaml.constructor.ConstructorError(
                None, None, "YAML aliases (*name) are not allowed in model files", event.start_mark
            )
        if isinstance(event, yaml.CollectionStartEvent):
            depth += 1
            if depth > MAX_YAML_DEPTH:
                raise RecursionError
        elif isinstance(event, yaml.CollectionEndEvent):
            depth -= 1
        if count > MAX_YAML_EVENTS:
            raise yaml.constructor.ConstructorError(
                None, None, f"more than {MAX_YAML_EVENTS} entries (values, keys, lists)", event.start_mark
            )


class _NoAliasLoader(_DuplicateKeyCheck, yaml.SafeLoader):
    """PyYAML's pure-Python safe loader (its messages are the clearer ones) with the
    duplicate-key check, refusing YAML aliases (they allow exponential 'billion laughs'
    blow-up)."""

    def compose_node(self, parent: yaml.Node | None, index: object) -> yaml.Node | None:
        if self.check_event(yaml.AliasEvent):
            event = self.peek_event()
            raise yaml.constructor.ConstructorError(
                None, None, "YAML aliases (*name) are not allowed in model files", event.start_mark
            )
        return super().compose_node(parent, index)


def read_yaml(path: str | os.PathLike[str], kind: str, error: type[Exception] = ModelFileError) -> Any:
    """Parse a YAML file defensively: a regular file of at most ``MAX_FILE_BYTES``, UTF-8,
    no aliases (alias bombs), no runaway nesting.  Every failure raises ``error`` with the
    file, and the line and column where the parser knows them; ``kind`` names the kind of
    file in the messages (model, geometry, study...).

    Raises:
        FileNotFoundError: when the file does not exist.
    """
    path = Path(path)
    size = path.stat().st_size
    if path.exists() and not path.is_file():  # a FIFO or a device would never end
        raise error(f"{path}: not a regular file")
    if size > MAX_FILE_BYTES:
        raise error(f"{path}: {size} bytes is too large for a {kind} file (limit {MAX_FILE_BYTES})")
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError as err:
        raise error(f"{path}: not UTF-8 text (byte {err.start}: {err.reason})") from None
    try:
        try:
            _check_events(text)
            return yaml.load(text, Loader=_FastLoader)
        except yaml.YAMLError:
            if len(text) > 100_000:  # libyaml's message (the pure-Python one would take seconds)
                raise
            return yaml.load(text, Loader=_NoAliasLoader)  # its messages are the clearer ones
    except yaml.YAMLError as err:
        mark = getattr(err, "problem_mark", None) or getattr(err, "context_mark", None)
        where = f"line {mark.line + 1}, column {mark.column + 1}: " if mark else ""
        problem = getattr(err, "problem", None) or str(err)
        raise error(f"{path}: {where}{problem}") from None
    except RecursionError:
        raise error(f"{path}: nested too deeply to be a {kind} file") from None
