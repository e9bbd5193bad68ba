"""Files that must never be half-written or trusted blindly.

Atomic writes (temporary file in the same folder, then ``os.replace``) for results and
checkpoints, a strict YAML reader (a key written twice is refused, not silently the last),
and the one loader of saved weights: ``torch.load(weights_only=True)`` with a
format tag, so a corrupt, truncated or foreign file is refused with an error naming it.

torch is imported lazily: the simulator itself never needs it.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import stat
import sys
import uuid
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import IO, Any

import yaml

__all__ = ["CheckpointError", "atomic_write", "temporary_path", "temporary_writer",
           "check_regular_file", "write_json", "save_torch", "load_torch",
           "save_checkpoint", "load_checkpoint", "built_from_checkpoint", "load_weights",
           "first_line", "read_yaml"]


class CheckpointError(ValueError):
    """A checkpoint file is missing, corrupt, foreign or does not fit what is asked of it."""


# The toolkit's temporary files are named ``.NAME.ipptk-PID-HEX.tmp``: the tag and the
# writer's PID let a run remove what a killed run of the toolkit left, and nothing else
# (an editor's or a download's ``*.tmp`` in the same folder is not the toolkit's to delete).
_TEMPORARY_TAG = "ipptk"
_TEMPORARY_NAME = re.compile(r"\..+\." + _TEMPORARY_TAG + r"-([1-9][0-9]{0,9})-[0-9a-f]{8}\.tmp")


def temporary_path(path: str | os.PathLike[str]) -> Path:
    """A fresh temporary name beside ``path`` (``.NAME.ipptk-PID-HEX.tmp``), for a file or
    folder written there and then renamed into place; :func:`temporary_writer` reads it."""
    path = Path(path)
    return path.with_name(f".{path.name}.{_TEMPORARY_TAG}-{os.getpid()}-"
                          f"{uuid.uuid4().hex[:8]}.tmp")


def temporary_writer(name: str) -> int | None:
    """The PID of the process that named ``name`` with :func:`temporary_path`, or None: not
    a temporary file of the toolkit."""
    match = _TEMPORARY_NAME.fullmatch(name)
    return int(match.group(1)) if match else None


def check_regular_file(path: str | os.PathLike[str], what: str = "file") -> None:
    """Refuse (ValueError naming the file) a path that is not a regular file: a FIFO, a
    device or a socket would block a reader forever or never end (``/dev/zero``), and is
    refused by its type before it is opened. A missing file raises FileNotFoundError, a
    folder IsADirectoryError (both OSError, naming the file)."""
    try:
        mode = os.stat(path).st_mode
    except OSError as err:
        raise type(err)(err.errno, err.strerror, os.fspath(path)) from None
    if stat.S_ISDIR(mode):
        raise IsADirectoryError(21, "is a folder, not a file", os.fspath(path))
    if not stat.S_ISREG(mode):
        kind = ("a FIFO (named pipe)" if stat.S_ISFIFO(mode) else
                "a device" if stat.S_ISCHR(mode) or stat.S_ISBLK(mode) else
                "a socket" if stat.S_ISSOCK(mode) else "not a regular file")
        raise ValueError(f"{what} {os.fspath(path)!r} is {kind}, not a regular file: refusing "
                         "to read it")


def atomic_write(path: str | os.PathLike[str], write: Callable[[IO[bytes]], None]) -> None:
    """Write ``path`` through a temporary file in the same folder and ``os.replace``.

    Args:
        path: the destination; its folder is created.
        write: called with a binary file handle open for writing.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = temporary_path(path)
    try:
        with open(tmp, "xb") as handle:
            write(handle)
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise


def write_json(path: str | os.PathLike[str], value: Any) -> None:
    """Atomically write ``value`` as indented JSON."""
    data = json.dumps(value, indent=1).encode("utf-8")
    atomic_write(path, lambda handle: handle.write(data))


def save_torch(path: str | os.PathLike[str], payload: Mapping[str, Any], kind: str) -> None:
    """Atomically save plain data (tensors, state dicts, numbers, strings) with a format tag.

    Args:
        path: destination file.
        payload: only types that ``torch.load(weights_only=True)`` accepts.
        kind: format tag checked by :func:`load_torch` (e.g. ``"ipp-toolkit/coma"``).
    """
    import torch

    data = _interned({"format": kind, **payload})
    atomic_write(path, lambda handle: torch.save(data, handle))


def _interned(value: Any) -> Any:
    """``value`` with every string in its dicts, lists and tuples interned.

    Pickle writes a string it has seen as a reference to the same object, so equal strings
    that are one object in one process and two in another (a config sent to a worker) would
    give files of the same content but other bytes; interned, equal strings are one object in
    every process and the same run saves the same bytes wherever it ran.
    """
    if isinstance(value, str):
        return sys.intern(value)
    if isinstance(value, dict):
        return {_interned(k): _interned(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return type(value)(_interned(v) for v in value)
    return value


def load_torch(path: str | os.PathLike[str], kind: str) -> dict[str, Any]:
    """Load a file written by :func:`save_torch` without unpickling code.

    Raises:
        CheckpointError: missing, unreadable, corrupt, or saved with another format tag.
    """
    import torch

    path = Path(path)
    try:
        check_regular_file(path, "checkpoint")
    except IsADirectoryError:
        raise CheckpointError(f"checkpoint {str(path)!r} is a folder, not a checkpoint file") \
            from None
    except FileNotFoundError:
        raise CheckpointError(f"checkpoint {str(path)!r} does not exist") from None
    except OSError as err:
        raise CheckpointError(f"cannot read checkpoint {str(path)!r}: {err.strerror}") from None
    except ValueError as err:  # a FIFO or a device: reading it would block or never end
        raise CheckpointError(str(err)) from None
    if path.stat().st_size == 0:
        raise CheckpointError(f"checkpoint {str(path)!r} is empty (0 bytes)")
    try:
        data = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as error:  # torch raises many types for corrupt or foreign files
        raise CheckpointError(f"checkpoint {str(path)!r} is corrupt or not a plain-weights file "
                              f"({type(error).__name__}: {first_line(error)})") from None
    if not isinstance(data, dict) or data.get("format") != kind:
        found = data.get("format") if isinstance(data, dict) else type(data).__name__
        raise CheckpointError(f"checkpoint {str(path)!r} is not an {kind!r} file "
                              f"(format tag: {found!r})")
    bad = _non_finite(data)
    if bad:
        raise CheckpointError(f"checkpoint {str(path)!r} holds non-finite values (NaN or inf) "
                              f"in {bad}: refusing to load it")
    return data


def _non_finite(value: Any, where: str = "") -> str:
    """The key path of the first floating tensor with a NaN or inf inside ``value``, or ''."""
    import torch

    if isinstance(value, torch.Tensor):
        return where or "the payload" if value.is_floating_point() and \
            not bool(torch.isfinite(value).all()) else ""
    if isinstance(value, Mapping):
        items = value.items()
    elif isinstance(value, list | tuple):
        items = enumerate(value)
    else:
        return ""
    for key, item in items:
        found = _non_finite(item, f"{where}.{key}" if where else str(key))
        if found:
            return found
    return ""


def first_line(error: BaseException) -> str:
    """The first line of an error's message, at most 200 characters (for one-line messages)."""
    return (str(error).splitlines() or [""])[0][:200]


def save_checkpoint(path: str | os.PathLike[str], payload: Mapping[str, Any], kind: str,
                    record: Any = None) -> Path:
    """Write ``payload`` with :func:`save_torch` (format tag ``kind``) and, given a JSON-safe
    ``record``, the JSON beside it (``path.with_suffix('.json')``), each atomically.

    Returns:
        ``path`` as a :class:`~pathlib.Path`.
    """
    path = Path(path)
    save_torch(path, payload, kind)
    if record is not None:
        write_json(path.with_suffix(".json"), record)
    return path


def load_checkpoint(path: str | os.PathLike[str], *kinds: str) -> dict[str, Any]:
    """:func:`load_torch` under the first of ``kinds`` the file is tagged with (e.g. a final
    policy or a training checkpoint of the same learner).

    Raises:
        CheckpointError: the file is none of ``kinds``; the message is the first kind's.
    """
    refused: CheckpointError | None = None
    for kind in kinds:
        try:
            return load_torch(path, kind)
        except CheckpointError as error:
            refused = refused or error
    if refused is None:
        raise ValueError("load_checkpoint needs at least one format tag")
    raise refused


def built_from_checkpoint(path: str | os.PathLike[str], build: Callable[[], Any]) -> Any:
    """``build()`` (the networks a checkpoint's records describe), with its ValueError (a
    network over the size limit, a grid too small) as a :class:`CheckpointError` naming the
    file."""
    try:
        return build()
    except ValueError as error:
        raise CheckpointError(f"checkpoint {str(path)!r}: {error}") from None


def load_weights(module: Any, state: Any, path: str | os.PathLike[str], problem: str) -> None:
    """``module.load_state_dict(state)``; weights that do not fit raise a
    :class:`CheckpointError` ``checkpoint PATH: PROBLEM (first line of torch's message)``."""
    try:
        module.load_state_dict(state)
    except (RuntimeError, TypeError, AttributeError, KeyError) as error:
        raise CheckpointError(f"checkpoint {str(path)!r}: {problem} "
                              f"({first_line(error)})") from None


class _StrictLoader(yaml.SafeLoader):
    """A safe YAML loader that refuses a key written twice in one mapping."""


def _strict_mapping(loader: _StrictLoader, node: yaml.MappingNode) -> dict[Any, Any]:
    seen: set[Any] = set()
    for key_node, _ in node.value:
        key = loader.construct_object(key_node)
        try:
            hash(key)
        except TypeError:  # a list or mapping as a key (``? [a, b]``): no file of ours has one
            raise yaml.constructor.ConstructorError(
                None, None, f"a key must be a plain value, not a {key_node.id}",
                key_node.start_mark) from None
        if key in seen:
            raise yaml.constructor.ConstructorError(
                None, None, f"duplicate key {key!r}", key_node.start_mark)
        seen.add(key)
    return loader.construct_mapping(node)


_StrictLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _strict_mapping)


#: How deep YAML may nest: a config is 2 levels deep; 100,000 nested brackets would exhaust
#: Python's recursion limit in the composer (a RecursionError traceback).
MAX_YAML_DEPTH = 64


def _no_anchors(loader: _StrictLoader, parent: Any, index: Any) -> Any:
    """Compose a node, refusing anchors (``&a``) and aliases (``*a``): a config needs neither,
    and a few hundred bytes of nested aliases expand to gigabytes (a "billion laughs");
    refusing also nesting deeper than :data:`MAX_YAML_DEPTH`."""
    event = loader.peek_event()
    if isinstance(event, yaml.events.AliasEvent) or getattr(event, "anchor", None) is not None:
        raise yaml.composer.ComposerError(
            None, None, "anchors and aliases (&name, *name) are not allowed in config files",
            event.start_mark)
    depth = getattr(loader, "_ipp_depth", 0)
    if depth >= MAX_YAML_DEPTH:
        raise yaml.composer.ComposerError(
            None, None, f"nested more than {MAX_YAML_DEPTH} levels deep", event.start_mark)
    loader._ipp_depth = depth + 1  # type: ignore[attr-defined]
    try:
        return yaml.composer.Composer.compose_node(loader, parent, index)
    finally:
        loader._ipp_depth = depth  # type: ignore[attr-defined]


_StrictLoader.compose_node = _no_anchors  # type: ignore[method-assign]


def read_yaml(path: str | os.PathLike[str], what: str = "file",
              check_size: Callable[[int, str], None] | None = None) -> Any:
    """Parse a YAML file safely, refusing a key written twice in one mapping.

    Args:
        path: the file.
        what: what the file is, for messages (``config file``).
        check_size: called as ``check_size(size_in_bytes, label)`` before the file is read
            (``label`` names ``what`` and the file); it raises to refuse a file too large
            (the config's size limit, :func:`ipp_toolkit.config.files.read_config_file`).

    Raises:
        ValueError: the file cannot be read, is not text or is not valid YAML (the message
            names ``what`` and the file).
    """
    path = Path(path)
    try:
        check_regular_file(path, what)  # a FIFO as --config would block forever
        if check_size is not None:
            check_size(path.stat().st_size, f"{what} {str(path)!r}")
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as err:
        why = err.strerror if isinstance(err, OSError) else "not a UTF-8 text file"
        raise ValueError(f"cannot read {what} {str(path)!r}: {why}") from None
    try:
        return yaml.load(text, Loader=_StrictLoader)
    except yaml.YAMLError as err:
        # One line: the problem and where (the parser's own message quotes the text).
        mark = getattr(err, "problem_mark", None)
        message = " ".join(str(getattr(err, "problem", None) or err).split())[:300]
        if mark is not None:
            message += f" (line {mark.line + 1}, column {mark.column + 1})"
        raise ValueError(f"{what} {str(path)!r} is not valid YAML: {message}") from None
