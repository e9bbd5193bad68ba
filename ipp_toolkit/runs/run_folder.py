"""Run folders: one run at a time, made and used by one command.

Every command that writes a run folder (``ipp-compare`` and :func:`evaluate`, ``ipp-train
coma``, ``ipp-train ppo``/``sb3``) claims it first with :func:`claim`, which

* checks the path: not empty, not a file, not under a file, writable;
* takes an exclusive ``fcntl.flock`` on ``OUT/.lock`` for the whole run, with this process's
  PID written in it: a second run into the folder (from any process) is refused, naming the
  holder's PID, instead of mixing or overwriting files;
* checks ``OUT/run.json``, which records the command that made the folder: another command
  is refused (an ``ipp-train coma`` run cannot overwrite an ``ipp-compare`` folder's
  ``config.json``). Folders written before ``run.json`` existed are recognised by their files.

A claim that ends in an error before the run wrote anything removes what the claim itself
made (the lock, the record, the folder), so refused input leaves nothing behind; a claim
removes the temporary files of runs killed mid-write.

This module owns those checks; the commands own what they store inside the folder.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import json
import os
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

__all__ = ["RunFolderError", "RunFolder", "claim", "check_out_path", "folder_command",
           "LOCK_NAME", "RECORD_NAME", "EVALUATION_COMMAND", "COMA_COMMAND"]

#: The command recorded in an evaluation folder (``ipp-compare`` and ``evaluate`` alike).
EVALUATION_COMMAND = "ipp-compare"
#: The command recorded in a COMA training folder.
COMA_COMMAND = "ipp-train coma"

LOCK_NAME = ".lock"
RECORD_NAME = "run.json"
_FORMAT = 1

# Folders written before run.json existed: which files say which command made them.
_LEGACY_MARKERS = (
    (COMA_COMMAND, ("last.pt", "best.pt", "warm_start.pt")),
    ("ipp-train ppo|sb3", ("checkpoint.pt", "policy.pt")),
)


class RunFolderError(ValueError):
    """A run folder cannot be used: a bad path, another run holds it, or another command made
    it."""


@dataclass
class RunFolder:
    """A claimed run folder (see :func:`claim`).

    Attributes:
        path: the folder.
        command: the command that holds it.
        created: paths the claim made (removed again if the run fails before writing).
        found: names in the folder when it was claimed.
    """

    path: Path
    command: str
    created: list[Path] = field(default_factory=list)
    found: frozenset[str] = frozenset()
    _fd: int = -1
    _depth: int = 1


_HELD: dict[Path, RunFolder] = {}  # folders this process holds, by resolved path


def check_out_path(path: str | os.PathLike[str], what: str = "--out") -> Path:
    """``path`` as a folder a run may be written to (RunFolderError naming it otherwise).

    Refused: an empty path (it would be the current folder), an existing file, a path below a
    file, and a path longer than the system allows.
    """
    if isinstance(path, bool) or not isinstance(path, str | os.PathLike):
        raise RunFolderError(f"{what} must be a folder path, got {path!r}")
    text = os.fspath(path)
    if not isinstance(text, str) or not text.strip():
        raise RunFolderError(f"{what} must name a folder, got {text!r} (the current folder is "
                             "not a run folder; give e.g. runs/NAME)")
    if "\0" in text:
        raise RunFolderError(f"{what} {text!r} holds a NUL character")
    folder = Path(text)
    for parent in (folder, *folder.parents):
        try:
            is_file = parent.exists() and not parent.is_dir()
        except OSError as err:
            raise RunFolderError(f"{what} {text!r} cannot be used: {err.strerror}") from None
        if is_file:
            where = "is a file" if parent == folder else f"is below the file {str(parent)!r}"
            raise RunFolderError(f"{what} {text!r} {where}; give a folder")
    return folder


def _read_record(folder: Path) -> str | None:
    """The command ``folder`` records, a legacy guess from its files, or None (no run)."""
    path = folder / RECORD_NAME
    if path.exists():
        try:
            record = json.loads(path.read_text(encoding="utf-8"))
            return str(record["command"])
        except (OSError, UnicodeDecodeError, ValueError, KeyError, TypeError) as err:
            raise RunFolderError(f"{str(path)!r} is unreadable ({err}); it should name the "
                                 "command that made the folder") from None
    config = folder / "config.json"
    if config.is_file():
        try:
            stored = json.loads(config.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, ValueError):
            stored = None
        if isinstance(stored, dict) and {"config", "seed", "namespace"} <= set(stored):
            return EVALUATION_COMMAND
        if isinstance(stored, dict) and "coma" in stored:
            return COMA_COMMAND
    for command, markers in _LEGACY_MARKERS:
        if any((folder / name).exists() for name in markers):
            return command
    return None


def folder_command(folder: str | os.PathLike[str]) -> str | None:
    """The command that made run folder ``folder`` (None: not a run folder, or missing)."""
    folder = Path(folder)
    return _read_record(folder) if folder.is_dir() else None


def _same_command(stored: str, command: str) -> bool:
    if "|" in stored:  # a legacy SB3 folder: the trainers' format tags tell them apart
        return command.startswith("ipp-train ppo") or command.startswith("ipp-train sb3")
    return stored == command


def _holder(lock: Path) -> str:
    try:
        pid = lock.read_text(encoding="ascii").strip()
    except (OSError, UnicodeDecodeError):
        pid = ""
    return f"process {pid}" if pid.isdigit() else "another process"


def _lock(folder: Path, run: RunFolder) -> None:
    """Take the folder's lock (non-blocking) and write this PID in it."""
    lock = folder / LOCK_NAME
    while True:
        existed = lock.exists()
        try:
            fd = os.open(lock, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o644)
        except OSError as err:
            raise RunFolderError(f"cannot write into {str(folder)!r}: {err.strerror}") from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as err:
            os.close(fd)
            if err.errno in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                raise RunFolderError(
                    f"{str(folder)!r} is in use by another run ({_holder(lock)}, lock file "
                    f"{str(lock)!r}); wait for it to end or use another folder") from None
            raise RunFolderError(f"cannot lock {str(lock)!r}: {err.strerror}") from None
        # A run that failed before writing removes its lock file; one opened just before that
        # is no longer the folder's lock: take the lock again on the file now in place.
        try:
            same = os.stat(lock).st_ino == os.fstat(fd).st_ino
        except FileNotFoundError:
            same = False
        if same:
            break
        os.close(fd)
    if not existed:
        run.created.append(lock)
    os.ftruncate(fd, 0)
    os.write(fd, f"{os.getpid()}\n".encode("ascii"))
    run._fd = fd


def _release(run: RunFolder, failed: bool) -> None:
    folder = run.path
    if failed and run.created:
        # Only what the claim made goes, and only while the run wrote nothing else.
        ours = {p.name for p in run.created} | run.found
        try:
            untouched = {p.name for p in folder.iterdir()} <= ours
        except OSError:
            untouched = False
        if untouched:
            for path in reversed(run.created):
                with contextlib.suppress(OSError):
                    path.rmdir() if path.is_dir() else path.unlink()
    with contextlib.suppress(OSError):
        os.ftruncate(run._fd, 0)
    os.close(run._fd)  # closing the descriptor releases the flock
    run._fd = -1


def _make_folder(folder: Path, created: list[Path]) -> None:
    """Create ``folder`` and its missing parents, remembering which were made."""
    missing = [p for p in (folder, *folder.parents) if not p.exists()]
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise RunFolderError(f"cannot create {str(folder)!r}: {err.strerror}") from None
    created.extend(reversed(missing))


def _is_temporary(name: str) -> bool:
    """Whether ``name`` is a half-written file: ``ipp_toolkit.io.atomic_write``'s
    ``.NAME.PID.HEX.tmp`` or a figure's ``.tmp-XXXX.png``."""
    return name.startswith(".") and (name.endswith(".tmp") or name.startswith(".tmp-"))


def _remove_stale_temporaries(folder: Path) -> None:
    """Remove what runs killed mid-write (SIGTERM, SIGKILL, power loss) left: under the lock
    no other run writes here, so every temporary file present is stale."""
    for path in folder.rglob(".*"):
        if _is_temporary(path.name) and path.is_file():
            with contextlib.suppress(OSError):
                path.unlink()


@contextlib.contextmanager
def claim(folder: str | os.PathLike[str], command: str, what: str = "--out"
          ) -> Iterator[RunFolder]:
    """Hold ``folder`` for a run of ``command`` (see the module docstring).

    Nested claims of one folder in one process (``ipp-compare`` around its evaluation) share
    the outer claim; another command's nested claim is refused like any other.

    Raises:
        RunFolderError: a bad path, the folder is held by another run, or was made by another
            command; nothing is written then.
    """
    path = check_out_path(folder, what)
    key = path.resolve()
    held = _HELD.get(key)
    if held is not None:
        if held.command != command:
            raise RunFolderError(f"{str(path)!r} is held by {held.command} in this process")
        held._depth += 1
        try:
            yield held
        finally:
            held._depth -= 1
        return
    stored = folder_command(path)  # refused early, before the folder is touched
    if stored is not None and not _same_command(stored, command):
        raise RunFolderError(f"{str(path)!r} was made by {stored.replace('|', '/')}, not "
                             f"{command}: use another folder")
    run = RunFolder(path, command)
    _make_folder(path, run.created)
    try:
        run.found = frozenset(p.name for p in path.iterdir())
    except OSError as err:
        raise RunFolderError(f"cannot read {str(path)!r}: {err.strerror}") from None
    failed = True
    try:
        _lock(path, run)
        # Read again under the lock: the folder may have changed hands since the first look.
        stored = _read_record(path)
        if stored is not None and not _same_command(stored, command):
            raise RunFolderError(f"{str(path)!r} was made by {stored.replace('|', '/')}, not "
                                 f"{command}: use another folder")
        record = path / RECORD_NAME
        if not record.exists():
            data = json.dumps({"format": _FORMAT, "command": command}, indent=1)
            try:
                with open(record, "x", encoding="utf-8") as handle:
                    handle.write(data)
            except OSError as err:
                raise RunFolderError(f"cannot write into {str(path)!r}: {err.strerror}") \
                    from None
            run.created.append(record)
        _remove_stale_temporaries(path)
        _HELD[key] = run
        try:
            yield run
        finally:
            del _HELD[key]
        failed = False
    finally:
        if run._fd >= 0:
            _release(run, failed)
        elif failed:
            for made in reversed(run.created):
                with contextlib.suppress(OSError):
                    made.rmdir()
