"""The commands' output folders: checked before any work starts
(:func:`check_output_place`) and written all or nothing (:func:`atomic_dir`),
never over a folder that holds anything the same command did not write.
"""

from __future__ import annotations

import fcntl
import os
import re
import shutil
import socket
import tempfile
from contextlib import ExitStack, contextmanager, suppress
from pathlib import Path

from .errors import SlamError
from .paths import CACHE_VARIABLE, cache_dir

# Output folders. A command replaces its --out folder only when the folder is empty or holds nothing but
# what the same command wrote there: its marker file lists every name it wrote. Work happens in a temporary
# folder beside the target, named ".<out>.helpers-partial.<host>.<pid>.<random>", which a later write into the
# same parent removes once that process is gone (a SIGKILL leaves it behind).
TEMPORARY = re.compile(
    r"\..+\.helpers-(partial|previous|probe)\.(?P<host>[A-Za-z0-9_-]+)\.(?P<pid>[0-9]+)\.[0-9a-f]{8}"
)
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
    that it never sees another writer's output half replaced."""
    with ExitStack() as stack:
        with suppress(OSError):  # no parent folder yet (or one we may not open): nobody swaps there
            stack.enter_context(_locked(Path(os.path.realpath(out_dir)).parent))
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
        with _locked(target.parent):
            _remove_stale(target.parent)
        work = _new_folder(target.parent, target.name, "partial")
        yield work
        _write_marker(work, marker)
        with _locked(target.parent):
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
    with _locked(parent):
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
    """``work`` takes the place of ``target``; the previous ``target`` is put
    back if that fails, and removed once it succeeds."""
    if not os.path.lexists(target):
        os.rename(work, target)
        return
    previous = target.parent / _new_name(target.name, "previous")
    os.rename(target, previous)
    try:
        os.rename(work, target)
    except BaseException:
        os.rename(previous, target)
        raise
    shutil.rmtree(previous, ignore_errors=True)  # what stays (a file we may not delete) goes with _remove_stale


def _new_name(name: str, kind: str) -> str:
    return f".{name}.helpers-{kind}.{_host()}.{os.getpid()}.{os.urandom(4).hex()}"


def _host() -> str:
    """This machine's name as a temporary folder carries it: a pid means something only on its own host."""
    return re.sub(r"[^A-Za-z0-9_-]", "_", socket.gethostname().split(".")[0])[:20] or "host"  # short paths


def _new_folder(parent: Path, name: str, kind: str) -> Path:
    """A new folder of ours beside ``name``, with the mode a plain mkdir gives (the umask's)."""
    while True:
        folder = parent / _new_name(name, kind)
        try:
            folder.mkdir()
            return folder
        except FileExistsError:
            continue


def _remove_stale(parent: Path) -> None:
    """Remove the temporary folders of ours in ``parent`` whose process,
    on this host, is gone: only names of our exact pattern, nothing else."""
    host = _host()
    for entry in os.scandir(parent):
        match = TEMPORARY.fullmatch(entry.name)
        if match and match["host"] == host and entry.is_dir(follow_symlinks=False) and not _alive(int(match["pid"])):
            shutil.rmtree(entry.path, ignore_errors=True)


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # another user's process, or a pid we cannot ask about: alive
        return True
    return True


@contextmanager
def _locked(folder: Path):
    """An exclusive lock on ``folder`` itself (flock on the directory: no lock file to leave behind)."""
    fd = os.open(folder, os.O_RDONLY | os.O_DIRECTORY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)


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
