"""Writing results so that an interrupted run never leaves half of one.

Every file is written under a temporary name in its own folder and renamed when complete;
a folder of results (a replay's ``--out``, a bag) is built under a temporary name beside its
final place and renamed into it at the end. An interrupted run (an error, Ctrl-C, SIGTERM)
therefore leaves either the old result or the new one. :func:`check_output` finds an output
that cannot be written before any work is done.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import IO, Any


class OutputError(Exception):
    """An output cannot be written where asked; the message names the path and the reason."""


def check_output(path: str | Path, *, kind: str = "folder", overwrite: bool = False) -> Path:
    """Check, before any work, that ``path`` can be written; raises :class:`OutputError`.

    ``kind``: ``"new"``, a path that must not exist (a bag); ``"file"``, a file that is
    replaced if it exists; ``"folder"``, a folder that may exist, but when it holds files
    already ``overwrite`` must be given (the old content is then replaced as a whole at the
    end, never mixed with the new).
    """
    path = Path(path)
    if path.exists() or path.is_symlink():
        if kind == "new":
            raise OutputError(f"{path} already exists; not overwriting it")
        if kind == "file" and path.is_dir():
            raise OutputError(f"{path} is a folder, not a file")
        if kind == "folder" and not path.is_dir():
            raise OutputError(f"{path} exists and is not a folder")
        if kind == "folder" and not overwrite and any(path.iterdir()):
            raise OutputError(
                f"{path} already holds files (of an earlier run?); pass --overwrite to replace "
                "them as a whole, or choose another folder"
            )
    _check_can_create_in(path.parent, path)
    return path


def _check_can_create_in(folder: Path, target: Path) -> None:
    """The nearest existing ancestor of ``folder`` is a folder we can create ``target`` in."""
    existing = folder
    while not existing.exists():
        if existing.is_symlink():  # a dangling link: nothing can be created through it
            raise OutputError(f"cannot create {target}: {existing} is a broken link")
        existing = existing.parent
    if not existing.is_dir():
        raise OutputError(f"cannot create {target}: {existing} is not a folder")
    try:  # the real test: permissions, read-only file systems, quotas
        probe = tempfile.mkdtemp(prefix=".mrm-probe-", dir=existing)
    except OSError as exc:
        raise OutputError(f"cannot create {target}: {existing}: {exc.strerror or exc}") from None
    os.rmdir(probe)


@contextlib.contextmanager
def staged_folder(final: str | Path) -> Iterator[Path]:
    """A fresh temporary folder beside ``final``; on success it replaces ``final`` (an old
    ``final`` is removed only after the new one is in place), on any error or interruption it
    is removed and ``final`` is left as it was."""
    final = Path(final)
    final.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f".{final.name}.partial-", dir=final.parent))
    staging.chmod(0o755)  # mkdtemp's 0700 would be the result's
    try:
        yield staging
        _replace(staging, final)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise


@contextlib.contextmanager
def staged_entries(folder: str | Path) -> Iterator[Path]:
    """A fresh temporary folder inside ``folder``, for outputs that share it with other
    files (``mrm demo``'s in ``--out``, beside its logs and whatever the user keeps there).
    On success each entry made in it replaces the entry of the same name in ``folder``, all
    at the end (one rename each), so the long work before never touches the old entries; on
    any error or interruption it is removed and ``folder`` is left as it was. Entries of
    ``folder`` that the run does not make are kept."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=".partial-", dir=folder))
    try:
        yield staging
        for entry in sorted(staging.iterdir()):
            _replace(entry, folder / entry.name)
    finally:
        shutil.rmtree(staging, ignore_errors=True)


def _replace(new: Path, final: Path) -> None:
    """Put ``new`` (a file or a folder) at ``final``, on the same file system. A file
    replaces a file in one atomic rename; otherwise an old ``final`` is moved aside first and
    removed only after the new one is in place."""
    if not (new.is_dir() or final.is_dir()):
        os.replace(new, final)
        return
    old = None
    if final.exists() or final.is_symlink():
        old = Path(tempfile.mkdtemp(prefix=f".{final.name}.old-", dir=final.parent))
        final.rename(old / final.name)
    new.rename(final)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


@contextlib.contextmanager
def staged_new(final: str | Path) -> Iterator[Path]:
    """A path with ``final``'s name inside a temporary folder beside it, for writers that create
    the path themselves (a rosbag2 writer names its files after its folder); moved to ``final``
    when complete, removed on any error or interruption. ``final`` must not exist."""
    final = Path(final)
    final.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f".{final.name}.partial-", dir=final.parent))
    try:
        yield staging / final.name
        if final.exists() or final.is_symlink():
            raise OutputError(f"{final} appeared while it was being written; not overwriting it")
        (staging / final.name).rename(final)
    finally:
        shutil.rmtree(staging, ignore_errors=True)


@contextlib.contextmanager
def atomic_file(path: str | Path, mode: str = "w") -> Iterator[IO[Any]]:
    """A file written under a temporary name in its folder and renamed to ``path`` only when
    complete (``os.replace``: readers see the old file or the new one, never part of one)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    handle, temporary = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(handle, mode) as stream:
            yield stream
        os.chmod(temporary, 0o644)  # mkstemp's 0600 would be the result's
        os.replace(temporary, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(temporary)
        raise


def atomic_write_text(path: str | Path, text: str) -> None:
    """Write ``text`` to ``path`` through :func:`atomic_file`."""
    with atomic_file(path) as stream:
        stream.write(text)
