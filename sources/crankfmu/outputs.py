"""Where results go: one output folder per command, files written only as regular files.

Every command that writes results takes one output folder (`--out DIR`; the Python API's
`out=`) and writes the files it names there, nothing elsewhere. Before any computation:

- `output_folder` finds or creates the folder and writes a probe file in it: a path that exists
  and is not a folder, a folder that cannot be created or written, is refused at once
  (OutputError: exit status 2), not after a run whose results would then be lost;
- `check_file` refuses each file name the command will write that exists as anything but a
  regular file (a folder, a FIFO, a device, a socket, a symbolic link even to a regular file):
  replacing it would destroy something that is not a result (`--out /dev/null` once replaced
  the machine's /dev/null, a FIFO was replaced by a regular file).

`atomic_write` writes through a temporary file in the same folder and renames it over the name
after checking the name again, so a reader sees the old file or the new one, never half of
one, and nothing but a regular file is ever replaced; `write_table` writes a CSV table so.
`open_regular` opens a file to be written in place (a table appended row by row) under the
same rule. `folder_lock` holds an exclusive lock on the folder itself (flock on the folder: no
lock file is left behind) while a set of files that belong together is written, so two
processes writing the same names at once cannot interleave their sets.
"""
from __future__ import annotations

import contextlib
import hashlib
import logging
import os
import stat
import tempfile
from pathlib import Path

from .errors import CrankfmuError

try:
    import fcntl
except ImportError:  # not POSIX: sets are written unlocked
    fcntl = None  # type: ignore[assignment]


class OutputError(CrankfmuError, ValueError):
    """An output folder or file that cannot be written, or that must not be replaced."""


_KINDS = ((stat.S_ISREG, "a regular file"), (stat.S_ISDIR, "a folder"),
          (stat.S_ISLNK, "a symbolic link"), (stat.S_ISFIFO, "a FIFO"),
          (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
          (stat.S_ISSOCK, "a socket"))


def _kind(mode: int) -> str:
    return next((name for test, name in _KINDS if test(mode)), "of an unknown kind")


def _reason(err: OSError) -> str:
    return err.strerror or str(err)


def output_folder(folder, option: str = "--out") -> Path:
    """`folder`, created if missing, checked to be a folder this process can write in (a probe
    file is created and removed). Raises OutputError naming `option`."""
    folder = Path(folder)
    try:
        mode = folder.stat().st_mode  # a symbolic link to a folder is that folder
    except FileNotFoundError:
        mode = None
    except (OSError, ValueError) as err:
        raise OutputError(f"{option} {folder}: cannot be used as the output folder "
                          f"({_reason(err) if isinstance(err, OSError) else err})") from None
    if mode is not None and not stat.S_ISDIR(mode):
        raise OutputError(f"{option} {folder}: exists and is {_kind(mode)}, not a folder; "
                          f"{option} names the output folder, where the command writes its "
                          "files under names it chooses")
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise OutputError(f"{option} {folder}: cannot create the output folder "
                          f"({_reason(err)})") from None
    try:
        fd, probe = tempfile.mkstemp(prefix=".crankfmu-probe-", dir=folder)
        os.close(fd)
        os.unlink(probe)
    except OSError as err:
        raise OutputError(f"{option} {folder}: cannot write in the output folder "
                          f"({_reason(err)})") from None
    return folder


def check_file(path, option: str = "--out") -> Path:
    """`path` if nothing is there or a regular file is (which may be replaced); raises
    OutputError when it exists as anything else."""
    path = Path(path)
    try:
        mode = os.lstat(path).st_mode
    except FileNotFoundError:
        return path
    except OSError as err:
        raise OutputError(f"{option}: cannot write {path} ({_reason(err)})") from None
    if not stat.S_ISREG(mode):
        raise OutputError(f"{option}: {path} exists and is {_kind(mode)}; results are written "
                          "only as regular files and never replace anything else: remove it or "
                          f"give another {option}")
    return path


def check_files(folder: Path, names, option: str = "--out") -> list[Path]:
    """The output folder checked (output_folder) and each file name in it (check_file)."""
    folder = output_folder(folder, option)
    return [check_file(folder / name, option) for name in names]


class _Sink:
    """A binary file that takes text or bytes and hashes what it is given."""

    def __init__(self, f):
        self._f, self.sha256 = f, hashlib.sha256()

    def write(self, data) -> int:
        if isinstance(data, str):
            data = data.encode()
        self.sha256.update(data)
        return self._f.write(data)


def atomic_write(path, write, option: str = "--out") -> str:
    """Call write(f) on a temporary file in `path`'s folder (f takes str or bytes), then rename
    it onto `path`; returns the sha256 of what was written. A reader (or a crash) sees the old
    file or the new one, never a half-written one; a name that is not a regular file (checked
    before and again just before the rename) is never replaced (OutputError)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    check_file(path, option)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name[:80]}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            sink = _Sink(f)
            write(sink)
        os.chmod(tmp, 0o666 & ~_umask())
        check_file(path, option)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise
    return sink.sha256.hexdigest()


def write_table(path, header, rows, option: str = "--out") -> Path:
    """A CSV table at `path`, written whole (atomic_write): the `header` row, then `rows`
    (sequences; an empty one is a blank line, so a second header can start another block)."""
    import csv

    def write(f) -> None:
        writer = csv.writer(f)
        writer.writerow(header)
        writer.writerows(rows)
    atomic_write(path, write, option)
    return Path(path)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def open_regular(path, option: str = "--out"):
    """A text file opened to be written from its start (truncated), only if `path` is missing
    or a regular file: never follows a symbolic link, never blocks on a FIFO (O_NONBLOCK at
    open), and checks what it opened before truncating it."""
    path = Path(path)
    check_file(path, option)
    flags = os.O_WRONLY | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_NONBLOCK", 0)
    try:
        fd = os.open(path, flags, 0o666)
    except OSError as err:
        raise OutputError(f"{option}: cannot write {path} ({_reason(err)})") from None
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            check_file(path, option)  # raises, naming what it is
            raise OutputError(f"{option}: {path} is not a regular file")
        os.set_blocking(fd, True)
        os.ftruncate(fd, 0)
        return os.fdopen(fd, "w", newline="")
    except BaseException:
        os.close(fd)
        raise


def remove_file(path) -> None:
    """Remove `path` if it is a regular file (an earlier set's member this set does not have)."""
    path = Path(path)
    with contextlib.suppress(FileNotFoundError):
        if stat.S_ISREG(os.lstat(path).st_mode):
            path.unlink()


@contextlib.contextmanager
def folder_lock(folder, option: str = "--out", wait: bool = True):
    """An exclusive lock on `folder` (flock on the folder itself) for the block. `wait` False:
    OutputError at once if another process holds it; True: wait for it (saying so on the log).
    On a filesystem without flock the block runs unlocked."""
    if fcntl is None:
        yield
        return
    fd = os.open(folder, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            if not wait:
                raise OutputError(f"{option} {folder}: another crankfmu process is writing "
                                  "there; wait for it to finish or give another "
                                  f"{option}") from None
            logging.getLogger("crankfmu").info("waiting for another crankfmu process writing "
                                               "%s", folder)
            fcntl.flock(fd, fcntl.LOCK_EX)
        except OSError:
            pass  # no flock here (some network filesystems)
        yield
    finally:
        os.close(fd)
