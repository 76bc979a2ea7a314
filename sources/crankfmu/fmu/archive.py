"""An FMU file, checked and unpacked: once per content, into a per-user cache.

`load_fmu` refuses, before anything is unpacked, what could escape or overflow the folder it is
unpacked into (zip member names that are not plain relative paths, sizes over the limits), a
modelDescription.xml that a safe parser would not read, and crankfmu FMUs whose bundled code is not
what its digest stands for or whose GUID is not its build's (fmu/bundle.py). It unpacks what a
co-simulation here uses (the description, this platform's binaries, the resources) into a folder
named by the SHA-256 of the FMU file in the user's cache (`cache_dir`): a later process finds it
there and unpacks nothing. A changed FMU file has another hash, so it can never meet the files of an
earlier content; a folder is written under a temporary name and renamed when whole, so processes
that unpack the same FMU at once each see a whole folder (the first rename wins); a cached folder is
checked before each use against the manifest written with it (the members' files, their sizes and
modification times) and unpacked again when it differs; it keeps the record of the checks its
content passed and its parsed model description (CheckedFmu), so that a later process neither
checks nor parses that content again; it is removed when unused for
CACHE_KEEP_SECONDS. Without a usable cache (CRANKFMU_CACHE_DIR set to "", a folder that is not this
user's alone) each process unpacks into a private temporary folder, removed at exit. Within a
process an FMU content is unpacked and loaded once: a shared library is never unloaded here (see
FmuInstance.terminate), so a new copy per run would grow the process by the library's size on every
run.
"""
from __future__ import annotations

import atexit
import contextlib
import errno
import functools
import hashlib
import io
import json
import os
import pickle
import shutil
import stat
import tempfile
import threading
import time
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

MAX_FMU_UNPACKED_BYTES = 1 << 30  # an FMU's files together, as its zip directory declares them
MAX_MEMBER_NAME_BYTES = 1024      # a member's name in the zip; a part of it at most NAME_MAX
NAME_MAX = 255                    # bytes in one file or folder name (Linux, most file systems)
CACHE_ENV = "CRANKFMU_CACHE_DIR"  # the cache folder; "" for none
CACHE_KEEP_SECONDS = 14 * 86400   # a cached FMU unused this long is removed (at a new unpack)
PART_PREFIX = ".part-"            # a folder being unpacked (left by a process that was killed)
PRIVATE_PREFIX = "crankfmu-fmu-"  # a process's own unpacked FMU, in the temporary folder
MANIFEST = ".crankfmu-files"      # in a cached folder: its files' sizes and times (_matches)
CHECKED = ".crankfmu-checked"     # in a cached folder: what load_fmu's checks found (CheckedFmu)
_loaded: dict[str, tuple[str, object]] = {}  # sha256 of an FMU file -> (folder, description)
_bundles: dict[str, object] = {}  # sha256 of an FMU file -> its bundle (inspected) or None
_private: set[str] = set()  # this process's folders, removed at exit: temporary, or part-done
_private_lock = threading.Lock()  # making such a folder, or removing them all: one at a time


class FmuRefused(ValueError):
    """An FMU file that is not loaded: its names, its size or its bundled code are not allowed
    (the message says which and what is allowed; the caller names the file)."""


def remove_unpacked(for_good: bool = False) -> None:
    """Remove this process's own folders: private unpacked FMUs and unpacking under way (at
    exit, or by a worker that ends early: `for_good`, no folder is made after this, by any
    thread). The cache stays."""
    _private_lock.acquire()
    try:
        for folder in list(_private):
            _discard(folder)
        _loaded.clear()
    finally:
        if not for_good:
            _private_lock.release()


def forget_private() -> None:
    """In a forked child: drop the parent's private folders and loaded FMUs from the records,
    leaving the folders (the parent removes them; the cache is shared)."""
    _private.clear()
    _loaded.clear()


def _new_private(prefix: str, parent: str | Path | None = None) -> str:
    """A new private folder `<prefix><pid>-<random>`: the pid lets the parent of a worker that
    was killed, and so could not remove its folders, find them (cosim/workers.py)."""
    with _private_lock:
        folder = tempfile.mkdtemp(prefix=f"{prefix}{os.getpid()}-", dir=parent)
        _private.add(folder)
    return folder


atexit.register(remove_unpacked)


def _discard(folder: str) -> None:
    remove_tree(folder)
    _private.discard(folder)


def remove_tree(folder: str | Path) -> None:
    """shutil.rmtree, again while files remain (another thread may still be writing there)."""
    for _ in range(3):
        shutil.rmtree(folder, ignore_errors=True)
        if not os.path.exists(folder):
            return


def _shortened(text: str, keep: int = 60) -> str:
    return text if len(text) <= keep else f"{text[:keep // 2]}...{text[-keep // 2:]}"


def fmu_file_problem(path: Path) -> str | None:
    """Why `path` names no FMU file that can be read (a sentence naming it), or None."""
    try:
        return None if Path(path).is_file() else f"no FMU file at {path}"
    except OSError as err:
        if err.errno != errno.ENAMETOOLONG:
            return f"cannot read the FMU file {_shortened(str(path))}: {err.strerror}"
    longest = max(Path(path).parts, key=lambda part: len(os.fsencode(part)))
    return (f"the FMU file name {_shortened(str(path))} is too long for the file system: a "
            f"file or folder name may have at most {NAME_MAX} bytes and a path "
            f"{os.pathconf('/', 'PC_PATH_MAX')}; this one has a name of "
            f"{len(os.fsencode(longest))} bytes in a path of {len(os.fsencode(str(path)))}")


def _member_problem(name: str) -> str | None:
    """What is wrong with a zip member's name, or None: a relative path with forward slashes,
    each part a plain name (not '', '.' or '..'), no drive, short enough to unpack anywhere."""
    parts = name.rstrip("/").split("/")
    if name.startswith("/") or "\\" in name or ":" in name or "\0" in name:
        return "an absolute name, a backslash, a drive or device colon or a NUL"
    if any(part in ("", ".", "..") for part in parts):
        return "an empty, '.' or '..' part"
    if len(name.encode()) > MAX_MEMBER_NAME_BYTES or \
            max(len(part.encode()) for part in parts) > NAME_MAX:
        return (f"a name longer than {MAX_MEMBER_NAME_BYTES} bytes or with a part longer than "
                f"{NAME_MAX} bytes")
    return None


def check_members(zf: zipfile.ZipFile) -> None:
    """Refuse an FMU whose zip has a member that could be unpacked outside its folder, or could
    not be unpacked, or that declares more than MAX_FMU_UNPACKED_BYTES in all."""
    for info in zf.infolist():
        problem = _member_problem(info.filename)
        if problem is not None:
            raise FmuRefused(f"zip member {_shortened(info.filename)!r} has {problem}; allowed "
                             "are relative paths of plain names joined by '/' (FMI 2.0, 2.1)")
    size = sum(i.file_size for i in zf.infolist())
    if size > MAX_FMU_UNPACKED_BYTES:
        raise FmuRefused(f"its files unpack to {size} bytes, more than the limit of "
                         f"{MAX_FMU_UNPACKED_BYTES} bytes")


def read_fmu(path: Path) -> tuple[bytes, str]:
    """(the FMU file's bytes, their SHA-256: the FMU's identity here), within the size limit."""
    if Path(path).stat().st_size > MAX_FMU_UNPACKED_BYTES:
        raise FmuRefused(f"larger than the limit of {MAX_FMU_UNPACKED_BYTES} bytes")
    data = Path(path).read_bytes()
    return data, hashlib.sha256(data).hexdigest()


def inspect_fmu(zf: zipfile.ZipFile, key: str):
    """Check an FMU (its open zip; `key`, its content's SHA-256) before anything is unpacked:
    member names and sizes (check_members), modelDescription.xml (check_model_description_xml)
    and its crankfmu bundle against its digest (fmu/bundle.py read_bundle); returns the bundle,
    or None for an FMU without one. Once per FMU content in this process."""
    from .bundle import BundleError, read_bundle
    if key not in _bundles:
        check_members(zf)
        check_model_description_xml(zf)
        try:
            _bundles[key] = read_bundle(zf)
        except BundleError as err:
            raise FmuRefused(str(err)) from None
    return _bundles[key]


def _needed(zf: zipfile.ZipFile) -> list[zipfile.ZipInfo]:
    """The members a simulation here uses: the description, this platform's binaries (under
    FMI 2.0's and FMI 3.0's name of the platform), the resources (not the documentation, the
    sources, other platforms' binaries)."""
    from fmpy import platform, platform_tuple
    return [i for i in zf.infolist() if not i.is_dir() and (
        i.filename == "modelDescription.xml" or i.filename.startswith(
            ("resources/", f"binaries/{platform}/", f"binaries/{platform_tuple}/")))]


def _unpack_into(folder: str, members: list[zipfile.ZipInfo], zf: zipfile.ZipFile) -> None:
    for info in members:
        target = os.path.join(folder, *info.filename.split("/"))
        os.makedirs(os.path.dirname(target), exist_ok=True)
        with zf.open(info) as src, open(target, "wb") as dst:
            shutil.copyfileobj(src, dst, 1 << 20)


def _private_folder(members, zf) -> str:
    folder = _new_private(PRIVATE_PREFIX)
    try:
        _unpack_into(folder, members, zf)
    except BaseException:
        _discard(folder)
        raise
    return folder


def cache_dir() -> Path | None:
    """The per-user folder FMUs are unpacked into: $CRANKFMU_CACHE_DIR, else
    $XDG_CACHE_HOME/crankfmu/fmus, else ~/.cache/crankfmu/fmus (made with mode 0700). None when
    the variable is set to "" or the folder cannot be made or is not this user's alone."""
    setting = os.environ.get(CACHE_ENV)
    if setting == "" or not hasattr(os, "getuid"):  # the ownership check below is POSIX's
        return None
    if setting is None:
        base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
        setting = os.path.join(base, "crankfmu", "fmus")
    try:
        os.makedirs(setting, mode=0o700, exist_ok=True)
        info = os.stat(setting)
    except OSError:
        return None
    private = info.st_uid == os.getuid() and not info.st_mode & (stat.S_IWGRP | stat.S_IWOTH)
    return Path(setting) if private and stat.S_ISDIR(info.st_mode) else None


def _write_manifest(folder: str, members: list[zipfile.ZipInfo]) -> None:
    """What _matches compares: each unpacked file's size and modification time."""
    files = {}
    for info in members:
        st = os.stat(os.path.join(folder, *info.filename.split("/")))
        files[info.filename] = [st.st_size, st.st_mtime_ns]
    Path(folder, MANIFEST).write_text(json.dumps(files))


def _matches(folder: Path, members: list[zipfile.ZipInfo]) -> bool:
    """The cached folder holds the members' files as they were unpacked: the manifest names
    exactly the members, and each file has the size and modification time it had then (an
    edited, truncated or removed file fails; one stat per file, no reading)."""
    try:
        files = json.loads((folder / MANIFEST).read_text())
        if set(files) != {i.filename for i in members}:
            return False
        for name, (size, mtime) in files.items():
            st = os.stat(os.path.join(folder, *name.split("/")))
            if (st.st_size, st.st_mtime_ns) != (size, mtime):
                return False
    except (OSError, ValueError, TypeError):
        return False
    return True


def _cached_folder(root: Path, key: str, members, zf) -> str:
    """The FMU's folder in the cache at `root`, unpacked there first when missing or not
    matching."""
    final = root / key
    if final.is_dir():
        if _matches(final, members):
            _touch(str(final))
            return str(final)
        aside = tempfile.mkdtemp(prefix=PART_PREFIX, dir=root)  # a damaged entry: replaced
        try:
            os.rename(final, os.path.join(aside, "old"))
        except OSError:  # another process replaced it meanwhile
            pass
        shutil.rmtree(aside, ignore_errors=True)
    part = _new_private(PART_PREFIX, root)
    try:
        _unpack_into(part, members, zf)
        _write_manifest(part, members)
        try:
            os.rename(part, final)
        except OSError:  # another process finished first: its folder is the same content
            if not (final.is_dir() and _matches(final, members)):
                raise
    finally:
        _discard(part)
    _evict(root, keep=final)
    return str(final)


def _touch(folder: str) -> None:
    """Mark a cached folder as in use (its time is what _evict reads)."""
    if folder not in _private:
        try:
            os.utime(folder)
        except OSError:
            pass


def _evict(root: Path, keep: Path) -> None:
    """Remove cached FMUs unused for CACHE_KEEP_SECONDS and unpacking folders left for an hour
    (a process killed while unpacking); the compiled launchers kept here
    (crankfmu.fmu.launcher) CACHE_KEEP_SECONDS after they were compiled, and one left half
    written after an hour."""
    now = time.time()
    for entry in os.scandir(root):
        try:
            age = now - entry.stat(follow_symlinks=False).st_mtime
        except OSError:
            continue
        stale = CACHE_KEEP_SECONDS if not entry.name.startswith((PART_PREFIX, ".launcher-")) \
            else 3600
        if entry.is_dir(follow_symlinks=False) and entry.path != str(keep) and age > stale:
            shutil.rmtree(entry.path, ignore_errors=True)
        elif entry.name.startswith(("launcher-", ".launcher-")) and age > stale:
            with contextlib.suppress(OSError):
                os.unlink(entry.path)


def load_fmu(path: Path) -> tuple[str, Any]:
    """(unpacked folder, model description) of the FMU file at `path`, checked, once per FMU
    content in this process (see the module's docstring). Refusals are FmuRefused (a
    ValueError); a file that is not a zip raises zipfile.BadZipFile."""
    data, key = read_fmu(path)
    if key in _loaded and os.path.isdir(_loaded[key][0]):
        _touch(_loaded[key][0])
        return _loaded[key]
    with zipfile.ZipFile(io.BytesIO(data)) as zf:
        members = _needed(zf)
        found = checked_fmu(key, members)  # checked when its cached folder was unpacked
        folder, checked = found if found is not None else _check_and_unpack(zf, key, members)
    _bundles[key] = checked.bundle
    _loaded[key] = folder, checked.description
    return _loaded[key]


def _check_and_unpack(zf: zipfile.ZipFile, key: str, members) -> tuple[str, CheckedFmu]:
    """Check the FMU (its open zip), unpack it into the cache (else into a folder of this
    process's own) and read its description; a cached folder keeps the record."""
    bundle = inspect_fmu(zf, key)
    root = cache_dir()
    folder: str | None
    try:
        folder = _cached_folder(root, key, members, zf) if root is not None else None
    except OSError:  # e.g. a full disk there: this process's own folder instead
        folder = None
    folder = folder or _private_folder(members, zf)
    checks = _checks_id()
    checked = CheckedFmu(checks or "", bundle, _described(folder, bundle))
    if folder not in _private and checks is not None:
        _write_checked(folder, checked)
    return folder, checked


def _described(folder: str, bundle):
    """The model description in the unpacked `folder`, checked against the FMU's `bundle`;
    the folder is discarded when it is this process's own and a check fails."""
    from fmpy import read_model_description

    from .bundle import BundleError, check_description
    try:
        description = read_model_description(os.path.join(folder, "modelDescription.xml"))
        if bundle is not None:
            check_description(bundle, description.modelName, description.version,
                              description.guid)
    except BaseException as err:
        if folder in _private:
            _discard(folder)
        if isinstance(err, BundleError):
            raise FmuRefused(str(err)) from None
        raise
    return description


@dataclass
class CheckedFmu:
    """What load_fmu's checks found for an FMU content: kept in its cached folder (CHECKED),
    so that a later process loads it without checking and parsing again (2 FMUs: about 15 ms
    of each run's start, and lxml's import). Written only after every check passed, into the
    folder named by the content's SHA-256, in a cache that is this user's alone (cache_dir):
    the folder's Python code, which every run executes, is trusted on the same grounds."""

    checks: str       # _checks_id() of the process that wrote it: another one ignores it
    bundle: Any       # fmu.bundle.Bundle, checked against its digest; None: not crankfmu's
    description: Any  # fmpy's ModelDescription, checked against the bundle


@functools.lru_cache(maxsize=None)
def _checks_id() -> str | None:
    """The checks a record stands for: this module's and fmu/bundle.py's code and fmpy's
    version (a changed check, or another parser of the description, ignores older records);
    None where that code cannot be read (no records then)."""
    import fmpy
    here = Path(__file__)
    try:
        code = here.read_bytes() + here.with_name("bundle.py").read_bytes()
    except OSError:  # e.g. imported from a zip
        return None
    return f"{hashlib.sha256(code).hexdigest()[:16]}-fmpy-{fmpy.__version__}"


def checked_fmu(key: str, members: list[zipfile.ZipInfo] | None = None
                ) -> tuple[str, CheckedFmu] | None:
    """(its cached folder, the record of its checks) of the FMU content `key` (its SHA-256),
    when the cache holds a record of this code and, given `members` (what _needed lists), the
    folder still matches them; else None."""
    root = cache_dir()
    if root is None or _checks_id() is None:
        return None
    folder = root / key
    try:
        with open(folder / CHECKED, "rb") as f:
            checked = pickle.load(f)
    except Exception:  # noqa: BLE001 - missing, half written or of other code: check again
        return None
    if not isinstance(checked, CheckedFmu) or checked.checks != _checks_id() or (
            members is not None and not _matches(folder, members)):
        return None
    _touch(str(folder))
    return str(folder), checked


def _write_checked(folder: str, checked: CheckedFmu) -> None:
    """Write the record of the checks into the cached `folder` (whole or not at all)."""
    from ..outputs import OutputError, atomic_write
    try:
        atomic_write(Path(folder, CHECKED),
                     lambda f: pickle.dump(checked, f, protocol=pickle.HIGHEST_PROTOCOL))
    except (OSError, OutputError, pickle.PicklingError):  # the next process checks again
        pass


def check_model_description_xml(fmu) -> None:
    """Refuse a modelDescription.xml that a safe parser would not read (fmpy parses it with
    lxml's defaults, which resolve entities): no DTD, no entities, well-formed, < 64 MiB.
    `fmu`: the FMU's path or its open zip."""
    if not isinstance(fmu, zipfile.ZipFile):
        with zipfile.ZipFile(fmu) as zf:
            return check_model_description_xml(zf)
    try:
        info = fmu.getinfo("modelDescription.xml")
    except KeyError:
        raise ValueError("no modelDescription.xml in the FMU") from None
    if info.file_size > 64 << 20:
        raise ValueError(f"modelDescription.xml declares {info.file_size} bytes")
    with fmu.open(info) as f:
        parse_safe_xml(f.read(64 << 20), "modelDescription.xml")


def parse_safe_xml(data: bytes, what: str):
    """An XML document parsed without DTD, entities or network access; a document that holds
    a DOCTYPE is refused (ValueError naming `what`)."""
    from lxml import etree
    parser = etree.XMLParser(resolve_entities=False, no_network=True, load_dtd=False,
                             dtd_validation=False, huge_tree=False, remove_comments=False)
    try:
        root = etree.fromstring(data, parser)
    except etree.XMLSyntaxError as err:
        raise UnsafeXml(f"{what} line {err.lineno}", f"not well-formed XML: {err.msg}") from None
    tree = root.getroottree()
    if tree.docinfo.doctype or tree.docinfo.internalDTD is not None:
        raise UnsafeXml(what, "a DOCTYPE (DTD, entities) is not allowed")
    return root


class UnsafeXml(ValueError):
    def __init__(self, where: str, message: str):
        self.where, self.message = where, message
        super().__init__(f"{where}: {message}")


