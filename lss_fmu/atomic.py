"""Atomic file writes: a reader (or a restarted run) sees either the old file
or the complete new one, never a half-written file.

The data goes to a temporary file in the same directory (so that the final
rename stays on one file system), is flushed and fsync'ed, and then replaces
the target with `os.replace`, which is atomic on POSIX and Windows. The
directory is fsync'ed too where the platform allows it, so the rename itself
survives a power cut. On any error the temporary file is removed and the
target is left as it was.
"""
from __future__ import annotations

import contextlib
import json
import os
import tempfile
from pathlib import Path
from typing import Any, Iterator, Union

try:
    import fcntl
except ImportError:   # Windows: no advisory locks; concurrent writers there are on their own
    fcntl = None

PathLike = Union[str, os.PathLike]


def _fsync_dir(directory: Path) -> None:
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:  # e.g. Windows: directories cannot be opened
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def write_atomic(path: PathLike, data: Union[bytes, str], encoding: str = "utf-8") -> Path:
    """Write `data` (bytes, or str encoded with `encoding`) to `path` atomically.
    Creates missing parent directories. Returns the path."""
    path = Path(path)
    if isinstance(data, str):
        data = data.encode(encoding)
    elif not isinstance(data, (bytes, bytearray, memoryview)):
        raise TypeError(f"write_atomic: data must be bytes or str, not {type(data).__name__}")
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        try:  # keep the permissions of the file being replaced, else the usual umask default
            mode = path.stat().st_mode & 0o7777
        except FileNotFoundError:
            umask = os.umask(0)
            os.umask(umask)
            mode = 0o666 & ~umask
        os.chmod(tmp, mode)
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise
    _fsync_dir(path.parent)
    return path


def write_json_atomic(path: PathLike, obj: Any, indent: int = 2, **dumps_kwargs: Any) -> Path:
    """Serialise `obj` as JSON (UTF-8, trailing newline) and write it atomically.
    The object is serialised completely before the file is touched, so an
    unserialisable object leaves the old file in place."""
    text = json.dumps(obj, indent=indent, **dumps_kwargs) + "\n"
    return write_atomic(path, text)


@contextlib.contextmanager
def locked(path: PathLike) -> Iterator[None]:
    """Hold an exclusive advisory lock on `path`.lock for a read-modify-write
    of `path` shared between processes (two campaigns writing one set's
    index: each must see the other's entries)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path.with_name(path.name + ".lock"), "a") as fh:
        if fcntl is not None:
            fcntl.flock(fh.fileno(), fcntl.LOCK_EX)
        try:
            yield
        finally:
            if fcntl is not None:
                fcntl.flock(fh.fileno(), fcntl.LOCK_UN)
