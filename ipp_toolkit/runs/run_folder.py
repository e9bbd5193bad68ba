"""Run folders: one run at a time, made and used by one command.

Every command that writes a run folder (``ipp-compare`` and :func:`evaluate`, ``ipp-train
coma``, ``ipp-train ppo``/``sb3``/``prior``, ``ipp-study``, ``ipp-simulate``) claims it first
with :func:`claim`, which

* checks the path: not empty, not a file, not under a file, not a symlink loop, writable;
* refuses a folder that holds files the toolkit did not write (no ``run.json`` and no files
  of an earlier run): ``--out .`` or ``--out ~`` would otherwise overwrite a user's own
  ``results.csv`` or ``summary.md``; ``force=True`` (``--force``) allows it;
* takes an exclusive ``fcntl.flock`` on the folder itself for the whole run (the process
  holds the lock, not a file: a deleted ``.lock`` lets no second run in, and a crashed run
  leaves no stale lock) and writes this process's PID in ``OUT/.lock`` for messages: a
  second run into the folder (from any process) is refused, naming the holder's PID;
* takes a shared ``flock`` on every folder above it: a run into a folder inside another
  run's folder, or into a folder that holds another run's folder, is refused (the outer
  run's clean-up and results would mix with the inner one's); a process's own nested runs
  (a study's comparisons inside its folder) share its claim;
* checks ``OUT/run.json``, which records the command that made the folder: another command
  is refused (an ``ipp-train coma`` run cannot overwrite an ``ipp-compare`` folder's
  ``config.json``). Folders written before ``run.json`` existed are recognised by their files.

A claim that ends in an error before the run wrote anything removes what the claim itself
made (the record, the folder), so refused input leaves nothing behind and deletes nothing. A
run that ends well removes the temporary files that runs of the toolkit killed mid-write left
in its folder, recognised by their names (:func:`ipp_toolkit.io.temporary_path`: the
toolkit's tag and the writer's PID, no longer running); no other file is touched, and no
folder of another run is entered.

This module owns those checks; the commands own what they store inside the folder.
"""

from __future__ import annotations

import contextlib
import contextvars
import errno
import fcntl
import json
import os
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

from ..io import temporary_writer

__all__ = ["RunFolderError", "RunFolder", "claim", "check_out_path", "folder_command",
           "allow_foreign_files", "LOCK_NAME", "RECORD_NAME", "EVALUATION_COMMAND", "COMA_COMMAND"]

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
    _parents: list[int] = field(default_factory=list)  # shared locks on the folders above


_HELD: dict[Path, RunFolder] = {}  # folders this process holds, by resolved path
_FORCE: contextvars.ContextVar[bool] = contextvars.ContextVar("ipp_force", default=False)


@contextlib.contextmanager
def allow_foreign_files(allow: bool = True) -> Iterator[None]:
    """Within the block, :func:`claim` accepts folders holding files the toolkit did not
    write (the commands' ``--force``; runs started inside, such as a trainer's, see it)."""
    token = _FORCE.set(bool(allow))
    try:
        yield
    finally:
        _FORCE.reset(token)


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
    try:
        folder.resolve()
    except (RuntimeError, OSError) as err:  # Python 3.11 raises RuntimeError on a loop
        why = getattr(err, "strerror", None) or "a symbolic link loop"
        raise RunFolderError(f"{what} {text!r} cannot be used: {why}") from None
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


def _holder(folder: Path) -> str:
    """Who holds ``folder``, for messages: ``process PID`` from its ``.lock``."""
    try:
        pid = (folder / LOCK_NAME).read_text(encoding="ascii").strip()
    except (OSError, UnicodeDecodeError):
        pid = ""
    return f"process {pid}" if pid.isdigit() else "another process"


_BUSY = (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES)


def _try_flock(fd: int, mode: int) -> bool:
    """``flock(fd, mode | LOCK_NB)``: False when another holder conflicts, True when taken
    or when the file system does not lock (nothing to check there)."""
    try:
        fcntl.flock(fd, mode | fcntl.LOCK_NB)
    except OSError as err:
        if err.errno in _BUSY:
            return False
    return True


def _open_folder(folder: Path) -> int:
    return os.open(folder, os.O_RDONLY | os.O_DIRECTORY | os.O_CLOEXEC)


#: The folders the runs of a process hold, for the processes it starts (a study's training
#: workers, a local Ray's workers inherit its environment): a run one of them claims inside
#: such a folder is part of that run, not another run's.
HOSTING_ENV = "IPP_TOOLKIT_HOSTING_RUNS"


def _hosting_folders() -> set[Path]:
    """The run folders held by the process that started this one (:data:`HOSTING_ENV`)."""
    return {Path(p) for p in os.environ.get(HOSTING_ENV, "").split(os.pathsep) if p}


@contextlib.contextmanager
def _hosting(key: Path) -> Iterator[None]:
    """Name ``key`` in :data:`HOSTING_ENV` while the run holds it, for its workers."""
    previous = os.environ.get(HOSTING_ENV)
    os.environ[HOSTING_ENV] = os.pathsep.join([*([previous] if previous else []), str(key)])
    try:
        yield
    finally:
        if previous is None:
            os.environ.pop(HOSTING_ENV, None)
        else:
            os.environ[HOSTING_ENV] = previous


def _lock_parents(folder: Path, key: Path, run: RunFolder) -> None:
    """Share-lock every folder above ``key`` (``folder`` resolved) but those this process
    holds or the process that started it holds; refuse when another run holds one of them
    (``folder`` would be inside it)."""
    hosting = _hosting_folders()
    for parent in key.parents:
        if parent in _HELD or parent in hosting:
            continue  # this process's own run, or its starter's: nested runs share its claim
        try:
            fd = _open_folder(parent)
        except OSError:
            continue  # an unreadable folder above: no run of ours can hold it either
        if not _try_flock(fd, fcntl.LOCK_SH):
            os.close(fd)
            raise RunFolderError(
                f"{str(folder)!r} is inside {str(parent)!r}, the folder of another run "
                f"({_holder(parent)}); use a folder outside it")
        run._parents.append(fd)


def _lock(folder: Path, run: RunFolder) -> None:
    """Lock ``folder`` itself (non-blocking) and write this PID in its ``.lock``."""
    try:
        fd = _open_folder(folder)
    except OSError as err:
        raise RunFolderError(f"cannot write into {str(folder)!r}: {err.strerror}") from None
    if not _try_flock(fd, fcntl.LOCK_EX):
        # Shared holders only: runs in folders below hold it; else a run holds it itself.
        below = _try_flock(fd, fcntl.LOCK_SH)
        os.close(fd)
        if below:
            raise RunFolderError(
                f"{str(folder)!r} holds the folder of another run below it; a run into it "
                "would mix with that run's files: use a folder beside it, not above it")
        raise RunFolderError(
            f"{str(folder)!r} is in use by another run ({_holder(folder)}, lock file "
            f"{str(folder / LOCK_NAME)!r}); wait for it to end or use another folder")
    run._fd = fd
    lock = folder / LOCK_NAME
    existed = lock.exists()
    try:
        with open(lock, "w", encoding="ascii") as handle:
            handle.write(f"{os.getpid()}\n")
    except OSError as err:
        raise RunFolderError(f"cannot write into {str(folder)!r}: {err.strerror}") from None
    if not existed:
        run.created.append(lock)


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
    lock = folder / LOCK_NAME
    if lock.is_file():
        with contextlib.suppress(OSError):
            os.truncate(lock, 0)  # no holder any more
    _unlock(run)


def _unlock(run: RunFolder) -> None:
    """Close the run's descriptors: closing them releases the locks."""
    for fd in [run._fd, *run._parents]:
        if fd >= 0:
            os.close(fd)
    run._fd, run._parents = -1, []


def _make_folder(folder: Path, created: list[Path]) -> None:
    """Create ``folder`` and its missing parents, remembering which were made."""
    missing = [p for p in (folder, *folder.parents) if not p.exists()]
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise RunFolderError(f"cannot create {str(folder)!r}: {err.strerror}") from None
    created.extend(reversed(missing))


def _running(pid: int) -> bool:
    """Whether process ``pid`` runs (this process counts: its writes may be in flight)."""
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:
        return True  # another user's process: running
    return True


#: How deep below a run folder the toolkit writes (``shards/LABEL/mission_00000.json``).
_WRITTEN_DEPTH = 2


def _remove_stale_temporaries(folder: Path, depth: int = 0) -> None:
    """Remove the toolkit's temporary files that runs killed mid-write (SIGTERM, SIGKILL,
    power loss) left in ``folder`` and the folders it writes: only names of
    :func:`ipp_toolkit.io.temporary_path` whose writer no longer runs. Folders of other runs
    (holding a ``run.json``), symbolic links and anything deeper than the toolkit writes
    (``--force`` into a home folder) are not entered."""
    try:
        entries = list(os.scandir(folder))
    except OSError:
        return
    for entry in entries:
        if entry.is_dir(follow_symlinks=False):
            if depth < _WRITTEN_DEPTH \
                    and not os.path.lexists(os.path.join(entry.path, RECORD_NAME)):
                _remove_stale_temporaries(Path(entry.path), depth + 1)
            continue
        pid = temporary_writer(entry.name)
        if pid is not None and entry.is_file(follow_symlinks=False) and not _running(pid):
            with contextlib.suppress(OSError):
                os.unlink(entry.path)


def _foreign_files(path: Path) -> list[str]:
    """Names in an existing ``path`` (no run record) that no run of the toolkit wrote."""
    try:
        names = sorted(entry.name for entry in os.scandir(path))
    except FileNotFoundError:
        return []
    except OSError as err:
        raise RunFolderError(f"cannot read {str(path)!r}: {err.strerror}") from None
    return [name for name in names if name != LOCK_NAME]


def _check_foreign(path: Path, force: bool) -> None:
    """Refuse a folder with files of its own and no record of a run (unless ``force``)."""
    if force or not path.is_dir() or _read_record(path) is not None:
        return
    foreign = _foreign_files(path)
    if foreign:
        shown = ", ".join(repr(name) for name in foreign[:5])
        more = f" and {len(foreign) - 5} more" if len(foreign) > 5 else ""
        raise RunFolderError(
            f"{str(path)!r} holds files no run of the toolkit wrote ({shown}{more}); a run "
            "would overwrite or mix with them: use a new folder, or --force (force=True) to "
            "write into it anyway")


def _check_command(path: Path, stored: str | None, command: str) -> None:
    if stored is not None and not _same_command(stored, command):
        raise RunFolderError(f"{str(path)!r} was made by {stored.replace('|', '/')}, not "
                             f"{command}: use another folder")


@contextlib.contextmanager
def claim(folder: str | os.PathLike[str], command: str, what: str = "--out",
          force: bool = False) -> Iterator[RunFolder]:
    """Hold ``folder`` for a run of ``command`` (see the module docstring).

    Nested claims of one folder in one process (``ipp-compare`` around its evaluation) share
    the outer claim; another command's nested claim is refused like any other.

    Args:
        force: accept a folder holding files the toolkit did not write (also within
            :func:`allow_foreign_files`).

    Raises:
        RunFolderError: a bad path, the folder is held by another run (or inside or above
            one), holds files of its own, or was made by another command; nothing is
            written or deleted then.
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
    _check_command(path, folder_command(path), command)  # before the folder is touched
    _check_foreign(path, force or _FORCE.get())
    run = RunFolder(path, command)
    failed = True
    try:
        _make_folder(path, run.created)
        _lock_parents(path, key, run)  # the folders made just now too
        try:
            run.found = frozenset(p.name for p in path.iterdir())
        except OSError as err:
            raise RunFolderError(f"cannot read {str(path)!r}: {err.strerror}") from None
        _lock(path, run)
        # Read again under the lock: the folder may have changed hands since the first look.
        _check_command(path, _read_record(path), command)
        _write_record(path, command, run)
        _HELD[key] = run
        try:
            with _hosting(key):
                yield run
        finally:
            del _HELD[key]
        failed = False
        _remove_stale_temporaries(path)
    finally:
        if run._fd >= 0:
            _release(run, failed)
        else:
            _unlock(run)
            for made in reversed(run.created):
                with contextlib.suppress(OSError):
                    made.rmdir()


def _write_record(path: Path, command: str, run: RunFolder) -> None:
    """Write ``run.json`` naming ``command`` where the folder has none yet."""
    record = path / RECORD_NAME
    if record.exists():
        return
    data = json.dumps({"format": _FORMAT, "command": command}, indent=1)
    try:
        with open(record, "x", encoding="utf-8") as handle:
            handle.write(data)
    except OSError as err:
        raise RunFolderError(f"cannot write into {str(path)!r}: {err.strerror}") from None
    run.created.append(record)
