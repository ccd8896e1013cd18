"""The commands' output folders: checked before any work starts
(:func:`check_output_place`) and written all or nothing (:func:`atomic_dir`),
never over a folder that holds anything the same command did not write.
"""

from __future__ import annotations

import ctypes
import errno
import logging
import os
import re
import shutil
import tempfile
from contextlib import ExitStack, contextmanager, suppress
from pathlib import Path

from helpers.errors import SlamError
from helpers.paths import CACHE_VARIABLE, cache_dir, dead_temporary, locked, temporary_name

log = logging.getLogger(__name__)

# Output folders. A command replaces its --out folder only when the folder is empty or holds nothing but
# what the same command wrote there: its marker file lists every name it wrote. Work happens in a temporary
# folder beside the target, named ".<out>.helpers-partial.<host>.<pid>.<random>" (helpers.paths.TEMPORARY),
# which a later write into the same parent removes once that process is gone (a SIGKILL leaves it behind).
# The previous output is never removed before the new one stands in its place (_swap).
MARKER_HEADER = "# Written by aerial-lidar-slam (python -m helpers):"


def check_output_place(out_dir: str | Path, marker: str, legacy: str | None = None) -> Path:
    """The resolved output folder ``out_dir`` of a command whose marker file
    is ``marker``, or a :class:`SlamError` saying why it cannot be written:
    a file, under a file, a mount point, an unexpanded ``~``, holding the current folder, inside
    the cache folder (:func:`cache_dir`, deleted at will), holding
    anything the command did not write, or in a folder we may not write.
    ``legacy``: the file that marked an output of an older version (no list
    of its files): such a folder is left for the user to delete by hand.
    The check holds the parent folder's lock, as a writer's swap does, so
    that it never sees another writer's output half replaced; an output a
    killed writer had set aside there is put back first (:func:`_remove_stale`)."""
    parent = Path(os.path.realpath(out_dir)).parent
    with ExitStack() as stack:
        try:
            stack.enter_context(locked(parent))
        except OSError:  # no parent folder yet (or one we may not open): nobody swaps there
            pass
        else:
            with suppress(OSError):
                _remove_stale(parent)
        return _check_place(out_dir, marker, legacy)


def _check_place(out_dir: str | Path, marker: str, legacy: str | None) -> Path:
    """:func:`check_output_place` without the lock."""
    given = Path(out_dir)
    if given.parts and given.parts[0].startswith("~") and not os.path.lexists(given.parts[0]):
        raise SlamError(  # a folder named "~" in the current one, which a later "rm -rf ~" would take for home
            f"output folder {given} starts with {given.parts[0]}, which the shell did not expand (it was quoted, "
            f"or followed '='): write {os.path.expanduser(given.parts[0])} instead"
        )
    target = Path(os.path.realpath(given))  # symbolic links followed first, then "..", as the kernel does
    for ancestor in target.parents:
        if os.path.lexists(ancestor):
            if not ancestor.is_dir():
                raise SlamError(f"output folder {given} lies under {ancestor}, which is a file, not a folder")
            break
    if os.path.lexists(target) and not target.is_dir():
        raise SlamError(f"output path {given} exists and is not a folder")
    if Path.cwd().is_relative_to(target):
        raise SlamError(f"output folder {given} holds the current folder: choose another")
    cache = Path(os.path.realpath(cache_dir()))
    if target.is_relative_to(cache):
        raise SlamError(
            f"output folder {given} lies inside the cache folder {cache}, which may be deleted at any time "
            f"(${CACHE_VARIABLE}): choose another"
        )
    if target.is_dir() and _is_mount_point(target):
        raise SlamError(f"output folder {given} is a mount point, which cannot be replaced: choose a folder inside it")
    try:
        _check_contents(given, target, marker, legacy)
    except OSError as exc:
        raise SlamError(f"output folder {given} cannot be read: {exc.strerror}") from None
    parent = next(a for a in target.parents if a.is_dir())
    try:  # the one sure test of "may I write here": try it (permissions, read-only file systems, root)
        os.rmdir(_new_folder(parent, target.name, "probe"))
    except OSError as exc:
        raise SlamError(f"output folder {given} cannot be written: {parent}: {exc.strerror}") from None
    return target


def _check_contents(given: Path, target: Path, marker: str, legacy: str | None) -> None:
    """Refuses a non-empty ``target`` unless everything in it is listed by its ``marker``."""
    if not (target.is_dir() and any(target.iterdir())):
        return
    written = _read_marker(target / marker)
    if written == "old" or (written is None and legacy and (target / legacy).exists()):
        raise SlamError(
            f"output folder {given} was written by an older version, which left no list of its files "
            f"({marker}): delete it by hand if nothing in it is yours, or choose another"
        )
    if written is None:
        raise SlamError(f"output folder {given} is not empty and holds no earlier {marker}: choose another")
    foreign = sorted(_entries(target) - written - {marker})  # walked only in a folder we marked
    if foreign:
        shown = ", ".join(foreign[:3]) + (f" and {len(foreign) - 3} more" if len(foreign) > 3 else "")
        raise SlamError(
            f"output folder {given} holds {len(foreign)} file(s) this tool did not write ({shown}): "
            "move them out or choose another"
        )


@contextmanager
def atomic_dir(out_dir: str | Path, marker: str, legacy: str | None = None):
    """Write a folder all or nothing: yields a temporary folder beside
    ``out_dir`` that replaces it when the block ends without error (and is
    removed otherwise), with ``marker`` listing what it holds. The place is
    checked by :func:`check_output_place` before and again at the swap,
    which holds a lock on the parent folder so that concurrent writers
    replace one another whole. An ``OSError`` (a full disk, a folder taken
    away) becomes a :class:`SlamError` naming the folder and the reason."""
    given = Path(out_dir)
    target = check_output_place(given, marker, legacy)
    created = [a for a in (target.parent, *target.parent.parents) if not os.path.lexists(a)]
    work = None
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        with locked(target.parent):
            _remove_stale(target.parent)
        work = _new_folder(target.parent, target.name, "partial")
        yield work
        _write_marker(work, marker)
        with locked(target.parent):
            _check_place(given, marker, legacy)  # the user may have put files there while we worked
            _swap(work, target)
    except BaseException as exc:
        if work is not None:
            shutil.rmtree(work, ignore_errors=True)
        for folder in created:  # the parents this call made, deepest first, if still empty
            with suppress(OSError):
                folder.rmdir()
        if isinstance(exc, OSError):
            where = _which_file(exc.filename, work, target)
            raise SlamError(f"cannot write output folder {given}{where}: {exc.strerror or exc}") from exc
        raise


@contextmanager
def scratch_dir(name: str):
    """A temporary folder of ours in the system's temporary folder, removed
    when the block ends; one that a killed process left there goes at the
    next call (as :func:`atomic_dir`'s do)."""
    parent = Path(tempfile.gettempdir())
    with locked(parent):
        _remove_stale(parent)
    folder = _new_folder(parent, name, "partial")
    try:
        yield folder
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def _which_file(filename, work: Path | None, target: Path) -> str:
    """The file an OSError names, as the error message shows it: relative to the output folder."""
    if not filename or Path(filename) == target:
        return ""
    if work is not None and Path(filename).is_relative_to(work):
        return f" ({Path(filename).relative_to(work)})"
    return f" ({filename})"


def _swap(work: Path, target: Path) -> None:
    """``work`` takes the place of ``target``. Both are exchanged in one step
    where the system can (:func:`_exchange`): a kill at any point leaves the
    old or the new output at ``target``. Elsewhere it takes two renames; the
    previous ``target`` is put back if the second fails, and a process killed
    between them leaves it for the next writer in the same parent to put back
    (:func:`_remove_stale`)."""
    if not os.path.lexists(target):
        os.rename(work, target)
        return
    if _exchange(work, target):
        shutil.rmtree(work, ignore_errors=True)  # now the previous output; what stays goes with _remove_stale
        return
    previous = target.parent / temporary_name(target.name, "previous")
    os.rename(target, previous)
    try:
        os.rename(work, target)
    except BaseException:
        os.rename(previous, target)
        raise
    shutil.rmtree(previous, ignore_errors=True)  # what stays (a file we may not delete) goes with _remove_stale


_AT_FDCWD, _RENAME_EXCHANGE = -100, 2
try:
    _renameat2 = ctypes.CDLL(None, use_errno=True).renameat2  # glibc 2.28 and later
    _renameat2.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_uint]
except (OSError, AttributeError):
    _renameat2 = None


def _exchange(a: Path, b: Path) -> bool:
    """Exchange two paths in one step (Linux's ``renameat2`` with ``RENAME_EXCHANGE``); False where the C
    library, the kernel or the file system cannot, an :class:`OSError` for any other refusal."""
    if _renameat2 is None:
        return False
    if _renameat2(_AT_FDCWD, os.fsencode(a), _AT_FDCWD, os.fsencode(b), _RENAME_EXCHANGE) == 0:
        return True
    code = ctypes.get_errno()
    if code in (errno.EINVAL, errno.ENOSYS, errno.EOPNOTSUPP):
        return False
    raise OSError(code, os.strerror(code), str(b))


def _new_folder(parent: Path, name: str, kind: str) -> Path:
    """A new folder of ours beside ``name``, with the mode a plain mkdir gives (the umask's)."""
    while True:
        folder = parent / temporary_name(name, kind)
        try:
            folder.mkdir()
            return folder
        except FileExistsError:
            continue


def _remove_stale(parent: Path) -> None:
    """Clear what writers of this host that are gone left in ``parent`` (only
    names of :data:`helpers.paths.TEMPORARY`'s exact pattern, nothing else):
    an output that a writer killed in the middle of its swap had set aside is
    put back where it was if nothing took its place; the rest is removed."""
    for entry in os.scandir(parent):
        match = dead_temporary(entry.name)
        if match is None or not entry.is_dir(follow_symlinks=False):
            continue
        target = parent / match["name"]
        if match["kind"] == "previous" and not os.path.lexists(target):
            try:
                os.rename(entry.path, target)
            except OSError as exc:
                log.warning("cannot put back output folder %s from %s: %s", target, entry.name, exc.strerror)
            else:
                log.warning(
                    "output folder %s put back: a process (pid %s) was killed while replacing it", target, match["pid"]
                )
            continue
        shutil.rmtree(entry.path, ignore_errors=True)


def _entries(folder: Path) -> set[str]:
    """Every file, folder and link under ``folder``, as relative POSIX paths."""
    found = set()
    for root, dirs, files in os.walk(folder, onerror=_raise):  # a folder we cannot read is not skipped
        here = Path(root).relative_to(folder)
        found.update((here / name).as_posix() for name in dirs + files)
    return found


def _raise(exc: OSError):
    raise exc


def _write_marker(folder: Path, marker: str) -> None:
    names = sorted(_entries(folder))
    header = f"{MARKER_HEADER} the same command may replace this folder while it holds only these files."
    (folder / marker).write_text("\n".join([header, *names]) + "\n")


def _read_marker(path: Path) -> set[str] | str | None:
    """The names a marker lists, "old" for a marker without a list, None without one."""
    if not path.is_file():
        return None
    lines = path.read_text(errors="replace").splitlines()
    if not lines or not lines[0].startswith(MARKER_HEADER):
        return "old"
    return set(lines[1:])


def _is_mount_point(folder: Path) -> bool:
    """A mount point, including a bind mount on the same device (``/proc/self/mountinfo``)."""
    if os.path.ismount(folder):
        return True
    try:
        lines = Path("/proc/self/mountinfo").read_text().splitlines()
    except OSError:
        return False
    points = {line.split()[4] for line in lines if len(line.split()) > 4}
    unescaped = {re.sub(r"\\([0-7]{3})", lambda m: chr(int(m[1], 8)), point) for point in points}  # \040: a space
    return str(folder) in unescaped
