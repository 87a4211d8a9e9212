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
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from bomi.errors import BomiError

TEMP_PREFIX = "."
TEMP_MARK = ".partial-"


def _one_line(exc: OSError) -> str:
    return exc.strerror or type(exc).__name__


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
    if path.is_dir():
        raise BomiError(f"{path}: is a directory, expected a file name")
    if path.exists() or path.is_symlink():
        if not overwrite:
            raise BomiError(f"{path}: file exists, not overwriting it" + (" (use --force to replace it)" if forceable else ""))
        if not path.is_file():
            raise BomiError(f"{path}: exists and is not a regular file")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise BomiError(f"{path}: directory {parent} is not writable")
    return path


def check_input(path: str | os.PathLike, what: str) -> Path:
    """``path`` as a Path if it is a readable file; else BomiError saying why (one line)."""
    path = Path(path)
    if path.is_dir():
        raise BomiError(f"{path}: is a directory, expected a {what} file")
    if not path.is_file():
        raise BomiError(f"{path}: no such {what} file")
    if not os.access(path, os.R_OK):
        raise BomiError(f"{path}: the {what} file is not readable (permission denied)")
    return path


def temp_sibling(path: Path) -> Path:
    """A new, empty temporary file beside ``path`` with the same suffix (created here, umask applies)."""
    for _ in range(100):
        temp = path.with_name(f"{TEMP_PREFIX}{path.stem}{TEMP_MARK}{secrets.token_hex(4)}{path.suffix}")
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
