"""Output folders and files of the twin: checked before the work, written atomically, never clobbering.

Every folder the twin writes holds a marker, ``.thermal-twin-output.json``,
listing the files the twin wrote there, the command and the project version.
The rules:

- an output that is a file where a folder is wanted (or a folder where a file
  is wanted), that is or holds an input of the command, or that cannot be
  created or written is refused at once, before any long work
  (:func:`check_output_folder`, :func:`check_output_file`);
- a non-empty folder without the marker is refused unless ``overwrite`` is
  given; even then the twin only adds its files beside the others. Only the
  files listed in the old marker are ever replaced or removed;
- the marker records which of the twin's commands wrote the folder (``run``,
  ``evaluate``, ``gap diagnose``…). Another command is refused unless
  ``overwrite`` is given: ``twin evaluate --out`` into a ``twin run`` folder had
  removed the run's dataset. A re-run of the same command, whatever its
  arguments, replaces and removes the listed files by itself, as before. A
  marker that names no command (an older version's, or one the Python API
  wrote) is taken as any command's, as before;
- results are written into a hidden staging folder inside the output folder
  and moved in when everything is there; the marker is written last, as the
  commit point. While files move, a journal (``.thermal-twin-output.partial.json``)
  lists every file the twin may own, so an interrupted commit leaves a folder
  the next run recognises as its own, but none that claims to be complete.

This module imports only the standard library: the command line checks
outputs before it loads the numerical libraries.
"""
from __future__ import annotations

import contextvars
import json
import os
import shlex
import shutil
import sys
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from datetime import datetime, timezone
from pathlib import Path, PurePosixPath

from ..core.files import sync_file, sync_folder, write_text_atomic
from ..core.interrupt import raise_if_interrupted
from ..errors import TwinInputError

MARKER = ".thermal-twin-output.json"
JOURNAL = ".thermal-twin-output.partial.json"
STAGING_PREFIX = ".thermal-twin-partial-"
MARKER_FORMAT = "thermal-twin-output"
#: The command a marker records when the caller names none; ``twin.cli.main`` sets it to ``twin <arguments>``.
COMMAND = contextvars.ContextVar("thermal_twin_command", default=None)
#: Which of the twin's commands is running (``run``, ``gap diagnose``), set by ``twin.cli.main``; None through the
#: Python API. A marker records it, and a folder another command wrote is refused without ``overwrite``.
JOB = contextvars.ContextVar("thermal_twin_job", default=None)


def _is_bookkeeping(name):
    return name in (MARKER, JOURNAL) or name.startswith(STAGING_PREFIX)


def _check_inputs(out, inputs):
    """Refuse an output that is, or is a folder holding, one of ``inputs`` (paths, or names that are no file)."""
    for given in inputs:
        path = Path(str(given)).expanduser().resolve() if given is not None else None
        if path is None or not path.exists():
            continue
        if path == out:
            raise TwinInputError(f"{out}: the output would replace an input of this command; choose another "
                                 "output")
        if out in path.parents:
            raise TwinInputError(f"{out}: the output folder holds an input of this command ({path}); choose "
                                 "another folder")


def _require_writable(path, folder):
    """Check that ``folder`` (``path`` or its parent) can be created and written: a probe in its nearest
    existing ancestor."""
    existing = folder
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():
        raise TwinInputError(f"{path}: cannot be created: {existing} is a file, not a folder")
    try:
        os.rmdir(tempfile.mkdtemp(prefix=".thermal-twin-probe-", dir=existing))
    except OSError as exc:
        raise TwinInputError(f"{path}: cannot write in {existing} ({exc.strerror})") from None


def check_output_folder(path: str | Path | None, overwrite: bool = False, inputs: tuple = ()) -> Path | None:
    """Check an output folder before the work.

    Parameters
    ----------
    path : str or Path or None
        The folder (None: no folder).
    overwrite : bool
        Accept a non-empty folder that is not a twin output (its files are kept), or one holding the
        result of another job (its listed files are replaced and removed).
    inputs : tuple of str or Path
        The command's inputs, which the folder must not be or hold.

    Returns
    -------
    Path or None
        The folder, resolved.

    Raises
    ------
    TwinInputError
        One line naming the path: it is a file, is or holds an input, cannot be
        created or written, or (``overwrite`` false) is a non-empty folder that
        is not a twin output or holds another job's result.
    """
    if path is None:
        return None
    out = Path(path).expanduser().resolve()
    if out.exists() and not out.is_dir():
        raise TwinInputError(f"{out}: is a file; the output must be a folder")
    _check_inputs(out, inputs)
    _require_writable(out, out)
    if out.exists() and not overwrite:
        records = _twin_records(out)
        if records:
            _check_same_job(out, records)
        elif any(not _is_bookkeeping(entry.name) for entry in out.iterdir()):
            raise TwinInputError(f"{out}: folder is not empty and is not a twin output (no {MARKER}); choose "
                                 "another folder, or pass --overwrite (overwrite=True) to write beside its "
                                 "files, which are kept")
    return out


def check_output_file(path: str | Path, overwrite: bool = False, inputs: tuple = (),
                      suffix: str | None = None) -> Path:
    """Check an output file before the work.

    Parameters
    ----------
    path : str or Path
        The file.
    overwrite : bool
        Accept an existing file (it is replaced).
    inputs : tuple of str or Path
        The command's inputs, which the file must not be.
    suffix : str, optional
        The ending the file's name must have (e.g. ``.npz``), when its format has one.

    Returns
    -------
    Path
        The file, resolved.

    Raises
    ------
    TwinInputError
        ``path`` is a folder, is one of ``inputs``, does not end in ``suffix``, cannot be created, or
        exists and ``overwrite`` is false.
    """
    out = Path(path).expanduser().resolve()
    if out.is_dir():
        raise TwinInputError(f"{out}: is a folder; the output must be a file")
    if suffix is not None and out.suffix != suffix:
        raise TwinInputError(f"{out}: the file is written as {suffix}; its name must end in {suffix}")
    _check_inputs(out, inputs)
    if out.exists() and not overwrite:
        raise TwinInputError(f"{out}: exists; pass --overwrite (overwrite=True) to replace it")
    _require_writable(out, out.parent)
    return out


def _safe_relative(name):
    """A listed file name as a relative path inside the folder, or ``None`` if it would leave it."""
    rel = PurePosixPath(str(name))
    if rel.is_absolute() or not rel.parts or ".." in rel.parts or _is_bookkeeping(rel.parts[0]):
        return None
    return rel.as_posix()


def _twin_records(folder):
    """The marker and an unfinished commit's journal in ``folder`` that are the twin's (marker first)."""
    records = []
    for name in (MARKER, JOURNAL):
        try:
            doc = json.loads((folder / name).read_text(encoding="utf-8"))
        except (OSError, ValueError):
            continue
        if isinstance(doc, dict) and doc.get("format") == MARKER_FORMAT and isinstance(doc.get("files"), list):
            records.append(doc)
    return records


def _owned_files(folder):
    """Files the twin wrote in ``folder`` (its marker and an unfinished commit's journal); ``None`` if neither."""
    records = _twin_records(folder)
    if not records:
        return None
    return {r for doc in records for r in map(_safe_relative, doc["files"]) if r is not None}


def _check_same_job(out, records):
    """Refuse ``out`` when its marker (or journal), the first of its ``records`` (:func:`_twin_records`), names
    another of the twin's commands than the running one (:data:`JOB`): its files are another command's result,
    which only ``overwrite`` may replace."""
    written, running = records[0].get("job"), JOB.get()
    if written is None or running is None or written == running:
        return
    state = "a complete" if (out / MARKER).exists() else "an unfinished"
    raise TwinInputError(f"{out}: holds {state} result of twin {written} ({records[0].get('command')}: "
                         f"{len(records[0]['files'])} files), which twin {running} would replace; choose another "
                         "folder, or pass --overwrite (overwrite=True) to replace that result")


def _write_json(path, document):
    write_text_atomic(path, json.dumps(document, indent=1) + "\n")


def _staged_files(staging):
    return sorted(p.relative_to(staging).as_posix() for p in staging.rglob("*") if not p.is_dir())


def _blocked(out, rel, owned):
    """Whether moving ``rel`` into ``out`` would replace something the twin did not write."""
    parts = PurePosixPath(rel).parts
    for i in range(1, len(parts)):
        parent = out.joinpath(*parts[:i])
        if (parent.is_symlink() or parent.exists()) and not parent.is_dir():
            return "/".join(parts[:i]) not in owned
    target = out / rel
    if target.is_dir() and not target.is_symlink():
        return True
    return (target.exists() or target.is_symlink()) and rel not in owned


def _remove_file(out, rel):
    target = out / rel
    if out not in target.parent.resolve().parents and target.parent.resolve() != out:
        return                                 # a linked folder leads outside: not the twin's to touch
    if target.is_symlink() or target.is_file():
        target.unlink()
    for parent in target.parents:              # folders the twin's files leave empty
        if parent == out:
            break
        try:
            parent.rmdir()
        except OSError:
            break


def _project_version():
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("thermal-twin")
    except PackageNotFoundError:  # pragma: no cover - running from a bare source tree
        return "unknown"


def _commit(staging, out, command):
    raise_if_interrupted()               # no result after a Ctrl-C, even one a library swallowed
    files = _staged_files(staging)
    owned = _owned_files(out) or set()
    blocked = [rel for rel in files if _blocked(out, rel, owned)]
    if blocked:
        more = f" (and {len(blocked) - 1} more)" if len(blocked) > 1 else ""
        raise TwinInputError(f"{out}: the twin would replace {blocked[0]}{more}, which it did not write; move "
                             "it away or choose another folder")
    head = {"format": MARKER_FORMAT, "version": 1, "project_version": _project_version(),
            "command": command or COMMAND.get() or shlex.join([Path(sys.argv[0]).name, *sys.argv[1:]]),
            "job": JOB.get()}
    _write_json(out / JOURNAL, {**head, "files": sorted(owned | set(files))})
    (out / MARKER).unlink(missing_ok=True)
    for rel in sorted(owned - set(files)):
        _remove_file(out, rel)
    for rel in files:
        sync_file(staging / rel)    # the marker below must never list a file whose content is not yet on disk
        target = out / rel
        target.parent.mkdir(parents=True, exist_ok=True)
        os.replace(staging / rel, target)
    for folder in {(out / rel).parent for rel in files}:
        sync_folder(folder)
    written = datetime.now(timezone.utc).isoformat(timespec="seconds")
    _write_json(out / MARKER, {**head, "written_utc": written, "files": files})   # the commit point
    (out / JOURNAL).unlink()


def _remove_stale_staging(out):
    """Staging folders that runs killed outright (no clean-up) left behind."""
    for entry in out.glob(f"{STAGING_PREFIX}*"):
        pid = entry.name[len(STAGING_PREFIX):]
        if pid.isdigit() and int(pid) != os.getpid() and not _alive(int(pid)):
            shutil.rmtree(entry, ignore_errors=True)


def _alive(pid):
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


@contextmanager
def atomic_directory(path: str | Path, overwrite: bool = False, inputs: tuple = (),
                     command: str | None = None) -> Iterator[Path]:
    """Yield a staging folder; on success its files are committed into the output folder ``path``.

    ``path`` is checked as :func:`check_output_folder` does. On success the
    files the twin wrote there before (its marker lists them) are replaced by
    the new ones and the marker is rewritten last; other files are never
    touched. On an exception (or Ctrl-C) the staging folder is removed and
    the output folder is left as it was. ``command`` is recorded in the
    marker (default: this process's command line).

    Parameters
    ----------
    path : str or Path
        The output folder.
    overwrite, inputs
        As :func:`check_output_folder`.
    command : str, optional
        Recorded in the marker.

    Yields
    ------
    Path
        The staging folder to write into.
    """
    out = check_output_folder(path, overwrite, inputs)
    created = not out.exists()
    out.mkdir(parents=True, exist_ok=True)
    _remove_stale_staging(out)
    staging = out / f"{STAGING_PREFIX}{os.getpid()}"
    shutil.rmtree(staging, ignore_errors=True)
    staging.mkdir()
    try:
        yield staging
        _commit(staging, out, command)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
        if created and not any(out.iterdir()):
            out.rmdir()
