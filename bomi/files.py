"""Writing output files safely: never half-written, never replacing a file unless asked.

Every output goes to a temporary sibling (same directory, so the final rename is atomic, and
the same suffix, so writers that pick a format by suffix still work), created with the
process's umask like any new file. On success it becomes the target: with ``overwrite`` by
``os.replace``; without, by a hard link that fails if the target appeared meanwhile. On any
failure the temporary file is removed and the target is untouched.
"""
from __future__ import annotations

import errno
import os
import secrets
import stat
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from bomi.errors import BomiError

TEMP_PREFIX = "."
TEMP_MARK = ".partial-"


def _one_line(exc: OSError) -> str:
    return exc.strerror or type(exc).__name__


def name_max(directory: Path) -> int:
    """The longest file name ``directory``'s file system accepts (NAME_MAX, 255 almost everywhere)."""
    try:
        return os.pathconf(directory, "PC_NAME_MAX")
    except (OSError, ValueError):
        return 255


def _lstat(path: Path, what: str) -> os.stat_result | None:
    """``path``'s own status (a symlink is not followed), None if there is nothing; any other OS
    error (a name too long, a directory that cannot be searched) is a one-line BomiError."""
    try:
        return os.lstat(path)
    except (FileNotFoundError, NotADirectoryError):
        return None
    except OSError as exc:
        raise BomiError(f"{path}: {what}: {_one_line(exc)}") from None


def check_output(path: str | os.PathLike, *, overwrite: bool = False, suffixes: tuple[str, ...] = (),
                 what: str = "output", forceable: bool = True) -> Path:
    """``path`` as a Path if a new file can be written there; else BomiError saying why (one line).
    ``forceable``: the command offers --force (the message says so)."""
    path = Path(path)
    if suffixes and path.suffix.lower() not in suffixes:
        raise BomiError(f"{path}: {what} must end in {' or '.join(suffixes)}")
    parent = path.parent
    if not parent.is_dir():
        raise BomiError(f"{path}: directory {parent} does not exist")
    if len(os.fsencode(path.name)) > name_max(parent):
        raise BomiError(f"{path}: {what}: file name longer than the {name_max(parent)} bytes the file system allows")
    status = _lstat(path, what)
    if status is not None and stat.S_ISDIR(status.st_mode):
        raise BomiError(f"{path}: is a directory, expected a file name")
    if status is not None:
        if not overwrite:
            raise BomiError(f"{path}: file exists, not overwriting it" + (" (use --force to replace it)" if forceable else ""))
        if not stat.S_ISREG(status.st_mode):
            raise BomiError(f"{path}: exists and is not a regular file (a symlink, FIFO or device is not replaced)")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise BomiError(f"{path}: directory {parent} is not writable")
    return path


# The largest input file read whole: far above any real one (P1's five-day recording is 0.1 GB a
# day), far below what would exhaust the memory of the machine reading it.
MAX_INPUT_BYTES = 4 << 30
# A configuration file (profile, participant, operator, grid, simulation) is a page of settings.
MAX_CONFIG_BYTES = 1 << 20


def check_input(path: str | os.PathLike, what: str, max_bytes: int = MAX_INPUT_BYTES) -> Path:
    """``path`` as a Path if it is a readable regular file of at most ``max_bytes``; else BomiError
    saying why (one line). A FIFO, a device or a directory is refused before it is opened (reading
    one would hang, or never end)."""
    path = Path(path)
    try:
        status = os.stat(path)
    except (FileNotFoundError, NotADirectoryError):
        raise BomiError(f"{path}: no such {what} file") from None
    except OSError as exc:
        raise BomiError(f"{path}: the {what} file cannot be read ({_one_line(exc)})") from None
    if stat.S_ISDIR(status.st_mode):
        raise BomiError(f"{path}: is a directory, expected a {what} file")
    if not stat.S_ISREG(status.st_mode):
        raise BomiError(f"{path}: is not a regular file (a FIFO, socket or device), expected a {what} file")
    if status.st_size > max_bytes:
        raise BomiError(f"{path}: {status.st_size} bytes, more than the {max_bytes} a {what} file may have")
    if not os.access(path, os.R_OK):
        raise BomiError(f"{path}: the {what} file is not readable (permission denied)")
    return path


def read_config_text(path: str | os.PathLike, what: str) -> str:
    """The text of a configuration file (UTF-8, at most MAX_CONFIG_BYTES); one-line BomiError otherwise."""
    path = check_input(path, what, MAX_CONFIG_BYTES)
    try:
        return path.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise BomiError(f"{path}: not valid TOML (not UTF-8 text)") from None
    except OSError as exc:
        raise BomiError(f"{path}: the {what} file cannot be read ({_one_line(exc)})") from None


def temp_sibling(path: Path) -> Path:
    """A new, empty temporary file beside ``path`` with the same suffix (created here, umask applies)."""
    # the stem cut so the temporary name fits where the final one does (NAME_MAX)
    room = name_max(path.parent) - len(os.fsencode(f"{TEMP_PREFIX}{TEMP_MARK}{'0' * 8}{path.suffix}"))
    stem = os.fsencode(path.stem)[:max(room, 1)].decode(errors="ignore")
    for _ in range(100):
        temp = path.with_name(f"{TEMP_PREFIX}{stem}{TEMP_MARK}{secrets.token_hex(4)}{path.suffix}")
        try:
            with open(temp, "xb"):
                return temp
        except FileExistsError:
            continue
        except OSError as exc:
            raise BomiError(f"{path}: cannot write in {path.parent} ({_one_line(exc)})") from None
    raise BomiError(f"{path}: cannot create a temporary file in {path.parent}")


def _commit(temp: Path, path: Path, overwrite: bool) -> None:
    if overwrite:
        os.replace(temp, path)
        return
    try:
        os.link(temp, path)  # fails if path exists: nothing is replaced
    except FileExistsError:
        raise BomiError(f"{path}: file exists, not overwriting it (use --force to replace it)") from None
    except OSError as exc:
        if exc.errno not in (errno.EPERM, errno.ENOTSUP, errno.EOPNOTSUPP, errno.EXDEV, errno.EMLINK):
            raise
        if path.exists():  # a file system without hard links: check, then rename
            raise BomiError(f"{path}: file exists, not overwriting it (use --force to replace it)") from None
        os.replace(temp, path)
        return
    temp.unlink()


@contextmanager
def atomic_output(path: str | os.PathLike, *, overwrite: bool = False) -> Iterator[Path]:
    """Yield a temporary path to write; on normal exit it becomes ``path``, on an exception it is removed."""
    path = Path(path)
    temp = temp_sibling(path)
    try:
        yield temp
        _commit(temp, path, overwrite)
    except OSError as exc:
        raise BomiError(f"{path}: cannot be written ({_one_line(exc)})") from None
    finally:
        temp.unlink(missing_ok=True)


def write_bytes(path: str | os.PathLike, data: bytes, *, overwrite: bool = False) -> None:
    with atomic_output(path, overwrite=overwrite) as temp:
        temp.write_bytes(data)


def write_text(path: str | os.PathLike, text: str, *, overwrite: bool = False) -> None:
    write_bytes(path, text.encode("utf-8"), overwrite=overwrite)
