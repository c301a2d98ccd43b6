"""Atomic file writes: a file appears complete under its final name, or not at all."""

from __future__ import annotations

import errno
import fcntl
import glob
import hashlib
import os
import re
import shutil
import stat
import tempfile
from collections.abc import Callable, Iterable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING

from vintix.errors import DiskSpaceError, OutputPathError

if TYPE_CHECKING:
    import torch

PARTIAL_SUFFIX = ".partial"
_UMASK = os.umask(0o022)
os.umask(_UMASK)  # read once: the process's umask, which files written atomically get as plain open() would give


MAX_NAME_BYTES = 160
"""The longest file name `file_name` makes (file systems allow 255 bytes; room for a suffix and a partial mark)."""


def file_name(name: str) -> str:
    """`name`, as a file supplied it (a task, a label, a group, a dataset id), turned into one file name that is never
    a path: every character but ASCII letters, digits, '-', '_' and '.' (after the first) becomes '_', so no '/',
    '..', NUL or control character gets through; a name that had to change, or was longer than `MAX_NAME_BYTES`,
    ends with a hash of the whole, so that two names never share a file."""
    safe = "".join(c if (c.isascii() and c.isalnum()) or c in "-_" or (c == "." and i) else "_"
                   for i, c in enumerate(name)) or "_"
    if safe == name and len(name.encode()) <= MAX_NAME_BYTES:
        return name
    digest = hashlib.sha256(name.encode("utf-8", "surrogatepass")).hexdigest()[:10]
    return f"{safe[:MAX_NAME_BYTES - len(digest) - 1]}-{digest}"


def byte_size(n_bytes: float) -> str:
    """A size as a person reads it: ``12 kB``, ``3.4 MB``, ``1.2 GB``."""
    for unit, scale in (("TB", 1e12), ("GB", 1e9), ("MB", 1e6)):
        if n_bytes >= scale:
            return f"{n_bytes / scale:,.1f} {unit}"
    return f"{n_bytes / 1e3:,.0f} kB"


def check_free_space(folder: str | os.PathLike[str], needed: int, what: str, fix: str) -> None:
    """A DiskSpaceError now, naming `folder`, the space `what` (a plural subject: "the histories", "the dataset
    would") needs and what it has, where the file system that will hold `folder` has less free than `needed` bytes:
    a full disk said before the work, not in its middle."""
    folder = Path(folder)
    existing = next(p for p in (folder, *folder.parents) if p.exists())
    free = shutil.disk_usage(existing).free
    if needed > free:
        raise DiskSpaceError(errno.ENOSPC, f"{folder}: {what} need about {byte_size(needed)}, and {existing} has "
                                           f"{byte_size(free)} free; {fix}")


def not_a_file(path: str | os.PathLike[str]) -> str | None:
    """What is wrong where `path` is there but is not a regular file (a FIFO, a device, a folder, a broken link), in
    words that name it; None where it is a file or nothing is there (the caller's "missing" is then the truth)."""
    path = Path(path)
    if path.is_file() or not (path.exists() or path.is_symlink()):
        return None
    return f"{path}: not a regular file (a FIFO, a device, a folder or a broken link); give a file"


def read_regular_text(path: str | os.PathLike[str]) -> str:
    """The text of the file at `path`, which must be a regular file: opened without blocking, so that a FIFO, a socket
    or a device given where a file is meant is an OSError naming it instead of a read that hangs for ever."""
    descriptor = os.open(path, os.O_RDONLY | os.O_NONBLOCK)
    try:
        if not stat.S_ISREG(os.fstat(descriptor).st_mode):
            raise OSError(errno.EINVAL, "not a regular file (a FIFO or a device would hang the read)", str(path))
        os.set_blocking(descriptor, True)
        with os.fdopen(descriptor, encoding="utf-8") as handle:
            descriptor = -1  # the handle closes it
            return handle.read()
    finally:
        if descriptor >= 0:
            os.close(descriptor)


def new_partial_file(path: str | os.PathLike[str]) -> Path:
    """A new, empty temporary file beside `path` that holds it until it is complete (same directory, so the
    final rename is atomic on POSIX filesystems): ``<name>.<random>.partial``, created exclusively, so a file or a
    symbolic link planted under a predictable name can never receive the write."""
    path = Path(path)
    handle, name = tempfile.mkstemp(dir=path.parent, prefix=f"{path.name}.", suffix=PARTIAL_SUFFIX)
    os.close(handle)
    return Path(name)


def remove_leftovers(path: str | os.PathLike[str]) -> None:
    """Delete the temporaries of `path` that a killed process left (`new_partial_file`'s). Only for a writer that
    holds `path`'s folder (`folder_lock`): another process's temporary in progress would go too. Unlinking removes
    a link itself, never what it points to."""
    path = Path(path)
    for leftover in path.parent.glob(f"{glob.escape(path.name)}*{PARTIAL_SUFFIX}"):
        if not leftover.is_dir():
            leftover.unlink(missing_ok=True)


def new_partial_folder(path: str | os.PathLike[str]) -> Path:
    """A new, empty temporary folder beside `path` to assemble it in, created exclusively (`new_partial_file`)."""
    path = Path(path)
    make_parent_dirs(path)
    folder = tempfile.mkdtemp(dir=path.parent, prefix=f"{path.name}.", suffix=PARTIAL_SUFFIX)
    os.chmod(folder, 0o777 & ~_UMASK)  # mkdir's, not mkdtemp's 0700
    return Path(folder)


def check_output_path(path: str | os.PathLike[str]) -> None:
    """Raise OutputPathError now if a file stands where one of `path`'s folders must be, so a long
    command fails before its work rather than when it saves the result. Creates nothing."""
    path = Path(path)
    _check_no_file_above(path, path.parents)
    if path.is_dir():
        raise OutputPathError(f"cannot write {path}: it is a directory; name a file")


def check_output_folder(folder: str | os.PathLike[str]) -> None:
    """Raise OutputPathError now if `folder`, or one of the folders it must be created in, is a file."""
    folder = Path(folder)
    _check_no_file_above(folder, [folder, *folder.parents])


def _check_no_file_above(path: Path, folders: Iterable[Path]) -> None:
    """Raise if the nearest of `folders` (those `path` needs, innermost first) that exists is a file, or a
    folder this process may not write in (a read-only file system, or no permission)."""
    blocking = next((p for p in folders if p.exists()), None)
    if blocking is not None and not blocking.is_dir():
        raise OutputPathError(f"cannot write {path}: {blocking} is a file, not a directory; choose another output "
                              "path or move the file")
    if blocking is not None and not os.access(blocking, os.W_OK | os.X_OK):
        raise OutputPathError(f"cannot write {path}: {blocking} is not writable here (a read-only file system, or "
                              "no permission); write elsewhere (--out) or fix the folder's permissions")


def make_parent_dirs(path: str | os.PathLike[str]) -> None:
    """Create the folder `path` goes in; a file standing where a folder must be is an OutputPathError
    naming that file (mkdir's own error names only the folder it wanted)."""
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except (FileExistsError, NotADirectoryError) as error:
        check_output_path(path)
        raise OutputPathError(f"cannot create the folder of {path}: {error}") from error


def publish(temporary: Path, final: str | os.PathLike[str]) -> None:
    """Give a finished temporary file its final name, and the permissions a plain open() would have given it
    (temporaries are created 0600, and a library writing one may replace it with a file of its own)."""
    # Without fsync, a crash shortly after the rename can leave the new name pointing at empty blocks.
    fd = os.open(temporary, os.O_RDONLY | os.O_NOFOLLOW)
    try:
        os.fchmod(fd, 0o666 & ~_UMASK)
        os.fsync(fd)
    finally:
        os.close(fd)
    os.replace(temporary, final)


@contextmanager
def atomic_path(path: str | os.PathLike[str]) -> Iterator[Path]:
    """Yield a temporary path beside `path`; publish it as `path` when the block succeeds, delete it
    when the block raises."""
    final = Path(path)
    make_parent_dirs(final)
    temporary = new_partial_file(final)
    try:
        yield temporary
        publish(temporary, final)
    except OSError as error:
        if error.filename is None:  # a failed write() names no file: name the one it was writing (a full disk)
            raise OSError(error.errno, error.strerror, str(final)) from error
        raise
    finally:
        temporary.unlink(missing_ok=True)


def atomic_write_text(path: str | os.PathLike[str], text: str) -> None:
    """Write `text` to `path` atomically."""
    with atomic_path(path) as temporary:
        temporary.write_text(text)


def atomic_save_tensors(tensors: dict[str, torch.Tensor], path: str | os.PathLike[str],
                        metadata: dict[str, str] | None = None) -> None:
    """safetensors' `save_file`, atomically. Its I/O failures (a full disk) are raised as the OSError of
    the failed system call naming `path`, like every other write: safetensors reports them as a
    SafetensorError that carries the errno only in its text."""
    # Imported here: the CLI imports this module, and `vintix --help` should not wait for torch.
    from safetensors import SafetensorError
    from safetensors.torch import save_file

    with atomic_path(path) as temporary:
        try:
            save_file(tensors, str(temporary), metadata=metadata)
        except SafetensorError as error:
            translated = os_error_in(error, r"os error (\d+)", path)
            if translated is None:
                raise
            raise translated from error


def os_error_in(error: Exception, pattern: str, path: str | os.PathLike[str]) -> OSError | None:
    """The OSError, naming `path`, of the system call behind a library's `error` whose text alone carries
    the errno (`pattern`'s one group), so that a full disk reads as one wherever it happens; None if the
    text has none."""
    found = re.search(pattern, str(error))
    if found is None:
        return None
    number = int(found.group(1))
    return OSError(number, os.strerror(number), str(path))


@contextmanager
def atomic_directory(directory: str | os.PathLike[str]) -> Iterator[Path]:
    """Yield a temporary folder beside `directory` to assemble it in; when the block succeeds it replaces
    `directory` whole, and when it raises (a full disk) it is deleted, leaving `directory` as it was."""
    directory = Path(directory)
    partial = new_partial_folder(directory)
    try:
        yield partial
        if directory.exists():
            shutil.rmtree(directory)
        os.replace(partial, directory)
    finally:
        shutil.rmtree(partial, ignore_errors=True)


LOCK_FILE = ".vintix-lock"
"""The file in an output folder that the command writing into it holds locked (`folder_lock`)."""


class FolderInUseError(OutputPathError):
    """Another process is already writing into the output folder."""


@contextmanager
def folder_lock(folder: str | os.PathLike[str], command: str) -> Iterator[None]:
    """Hold `folder` for `command` while the block runs: a second collection or training into the same
    folder fails at once, naming the first, instead of both writing the same files. The lock is the
    kernel's (flock), so a process that dies, however it dies, releases it."""
    folder = Path(folder)
    check_output_folder(folder)
    created = not folder.exists()
    folder.mkdir(parents=True, exist_ok=True)
    try:
        with _locked(folder, command):
            yield
    finally:
        # A command that failed before writing anything (a bad setting found after the lock was
        # taken) leaves no folder behind that says it ran.
        if created and [p.name for p in folder.iterdir()] == [LOCK_FILE]:
            (folder / LOCK_FILE).unlink()
            folder.rmdir()


def check_folder_entries(folder: str | os.PathLike[str]) -> None:
    """OutputPathError naming the first entry of `folder` (at any depth) that is a symbolic link or neither a
    regular file nor a folder (a FIFO, a socket, a device). Commands write into their folders by name (the lock,
    logs, results) and read back what is there: a link planted in a downloaded dataset or run would carry a
    write to any file the user can write, and a FIFO would hang a read. The folder itself may be a link."""
    for root, folders, files in os.walk(folder):  # os.walk never descends into a linked folder
        for name in folders + files:
            path = Path(root) / name
            mode = os.lstat(path).st_mode
            if stat.S_ISLNK(mode) or not (stat.S_ISREG(mode) or stat.S_ISDIR(mode)):
                kind = "a symbolic link" if stat.S_ISLNK(mode) else "a FIFO" if stat.S_ISFIFO(mode) else \
                    "a special file"
                raise OutputPathError(f"{path} is {kind}; vintix writes and reads its output folders by name, so it "
                                      f"refuses {folder} while it holds one: remove it (or copy what it points to in "
                                      "its place)")


@contextmanager
def _locked(folder: Path, command: str) -> Iterator[None]:
    check_folder_entries(folder)
    try:  # O_NOFOLLOW: the lock itself never follows a link (one planted after the check, say)
        descriptor = os.open(folder / LOCK_FILE, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW, 0o644)
    except OSError as error:
        if error.errno != errno.ELOOP:
            raise
        raise OutputPathError(f"{folder / LOCK_FILE} is a symbolic link; remove it") from None
    with os.fdopen(descriptor, "r+") as handle:
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            handle.seek(0)
            holder = handle.read().strip() or "another vintix process"
            raise FolderInUseError(
                f"{folder} is in use by {holder}; wait for it to end, or write to another folder") from None
        handle.seek(0)
        handle.truncate()
        handle.write(f"{command} (pid {os.getpid()})\n")
        handle.flush()
        try:
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)


OUTPUT_KINDS: dict[str, tuple[str, Callable[[Path], bool]]] = {
    "dataset": ("a dataset (learning histories)", lambda folder: any(folder.glob("*/*/*.h5"))),
    "run": ("a training run", lambda folder: (folder / "checkpoints").is_dir() or (folder / "log.csv").is_file()),
    "results": ("evaluation results", lambda folder: (folder / "episodes.csv").is_file()),
    "report": ("a report", lambda folder: (folder / "report.md").is_file()),
    "checkpoint": ("a checkpoint", lambda folder: (folder / "model.safetensors").is_file()),
    "release": ("a release snapshot in the authors' format", lambda folder: (folder / "model.pth").is_file()),
}
"""What each command writes into its output folder, and how to recognize it there."""


def check_replaceable(folder: str | os.PathLike[str], kind: str, overwrite: bool,
                      inputs: Sequence[str | os.PathLike[str]] = ()) -> None:
    """Raise OutputPathError where writing `kind` (a key of OUTPUT_KINDS) into `folder` would destroy something:
    a folder that is one of the command's own `inputs` (always), a folder holding another kind of output
    (always: the two would mix), or a non-empty folder (unless `overwrite`; `vintix eval` lets a run replace its own
    earlier results, `vintix.evaluate.run.check_results_folder`). The one rule every command that writes a model or
    results follows."""
    folder = Path(folder)
    for source in inputs:
        if Path(source).resolve() == folder.resolve():
            raise OutputPathError(f"{folder} is this command's own input; writing {OUTPUT_KINDS[kind][0]} there would "
                                  "destroy it: choose another output folder")
    check_output_kind(folder, kind)
    if folder.is_dir() and any(p.name != LOCK_FILE for p in folder.iterdir()) and not overwrite:
        held = next((what for what, holds in OUTPUT_KINDS.values() if holds(folder)), "files")
        raise OutputPathError(f"{folder} already holds {held}; writing {OUTPUT_KINDS[kind][0]} there would replace "
                              "it: choose another output folder, or pass --overwrite")


def check_output_kind(folder: str | os.PathLike[str], kind: str) -> None:
    """Raise OutputPathError if `folder` already holds another kind of output than `kind` (a key of
    OUTPUT_KINDS): writing a training run into a dataset, or results into a run, would mix the two."""
    folder = Path(folder)
    if not folder.is_dir():
        return
    for other, (what, holds) in OUTPUT_KINDS.items():
        if other != kind and holds(folder):
            raise OutputPathError(f"{folder} already holds {what}; writing {OUTPUT_KINDS[kind][0]} into it would mix "
                                  "the two: choose another output folder")
