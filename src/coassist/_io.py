"""Crash-safe file output: the one place coassist writes files and folders.

Three guarantees, whatever kills the process (an exception, Ctrl-C, SIGKILL, power loss):

- **A file is whole or absent.** :func:`atomic_write` writes a temporary file beside the
  destination, fsyncs it, ``os.replace``-s it over the destination and fsyncs the folder,
  so the rename itself is on disk. Readers see the old bytes or the new ones.
- **A folder is swapped whole.** :func:`swap_in` puts a folder written beside the
  destination (a dataset, a model) in its place with one atomic ``renameat2(EXCHANGE)``
  (Linux); elsewhere with two renames, undone by :func:`remove_stale` if a crash falls
  between them. The old folder stays complete until the new one is.
- **One writer per output.** :class:`OutputLock` holds an advisory ``flock`` on a
  ``.<name>.lock`` file beside the output while a run writes it; a second run gets
  :class:`OutputBusyError`. The kernel drops the lock when its process dies, so a
  killed run never leaves a stale lock (at most an unlocked file, reused).

Temporary names carry the writer's pid (``.<name>.<pid>.<token>.tmp``, ``….new``), so
:func:`remove_stale` can delete what a dead process left behind and nothing a live one
is still writing. Files are created with mode 0666 and folders 0777, less the user's
umask, as ``open``/``mkdir`` would (``tempfile`` would give 0600 / 0700).

**Hashed JSON files** (:func:`write_hashed_json`, :func:`read_hashed_json`): a small JSON
object that carries the SHA-256 of its own content, for the files a person could edit by
hand and the robot would then obey (a path-hypotheses calibration, a learned person
model). The hash is over the canonical JSON of the object without the hash key
(:func:`json_sha256`: sorted keys, no spaces, ASCII, no NaN or infinity); an edit that
does not recompute it is refused in one line naming the file. It guards against an edit
by mistake (a typo, a value pasted from elsewhere), not against someone who recomputes it.
"""

from __future__ import annotations

import ctypes
import errno
import hashlib
import io
import json
import os
import re
import secrets
import shutil
from collections.abc import Callable, Iterable, Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Any

from coassist.errors import CoassistError

__all__ = [
    "json_object_with",
    "HASH_KEY",
    "HashedJsonError",
    "OutputBusyError",
    "OutputLock",
    "atomic_write",
    "atomic_write_bytes",
    "atomic_write_text",
    "figure_bytes",
    "fsync_dir",
    "json_sha256",
    "no_constant",
    "no_duplicate_keys",
    "partial_folder",
    "read_hashed_json",
    "remove_stale",
    "save_figure",
    "staged_folder",
    "swap_in",
    "write_hashed_json",
]

# .<name>.<pid>.<token>.<kind>, kind = tmp (a file being written), new (a folder being
# written), old (a folder being swapped out, fallback path only).
_TEMP = re.compile(r"^\.(?P<name>.+)\.(?P<pid>\d+)\.(?P<token>[0-9a-f]{8})\.(?P<kind>tmp|new|old)$")


class OutputBusyError(CoassistError, RuntimeError):
    """Another run is writing the same output; the message names it and the lock file."""


def temp_name(name: str, kind: str) -> str:
    """A hidden sibling name for a file or folder being written (``.name.<pid>.<random>.kind``), unique per process."""
    return f".{name}.{os.getpid()}.{secrets.token_hex(4)}.{kind}"


def partial_folder(dest: str | os.PathLike[str]) -> Path:
    """Where an interrupted run keeps what it finished for ``dest``: ``.<name>.partial`` beside it.

    Unlike the pid-named temporaries, it outlives its writer on purpose, so that a
    re-run can continue (collect's trials, train's last epoch).
    """
    dest = Path(dest)
    return dest.parent / f".{dest.name}.partial"


def fsync_dir(folder: str | os.PathLike[str]) -> None:
    """Persist the entries of ``folder`` (renames, creations); a no-op where unsupported."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def _pid_alive(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # exists, owned by someone else
        return True
    return True


def remove_stale(folder: str | os.PathLike[str], name: str | None = None) -> list[Path]:
    """Delete the temporary files and folders that dead writers left in ``folder``.

    ``name`` limits the sweep to the temporaries of one destination. A ``.old`` folder
    whose destination is missing (a crash between the two renames of the fallback
    swap) is renamed back into place instead. Returns what was removed or restored.
    """
    folder = Path(folder)
    done: list[Path] = []
    try:
        entries = list(os.scandir(folder))
    except (FileNotFoundError, NotADirectoryError):
        return done
    for entry in entries:
        m = _TEMP.match(entry.name)
        if not m or (name is not None and m["name"] != name) or _pid_alive(int(m["pid"])):
            continue
        path = Path(entry.path)
        dest = folder / m["name"]
        try:
            if m["kind"] == "old" and not dest.exists():
                os.rename(path, dest)
            elif entry.is_dir(follow_symlinks=False):
                shutil.rmtree(path)
            else:
                path.unlink()
        except FileNotFoundError:
            continue
        done.append(path)
    if done:
        fsync_dir(folder)
    return done


def atomic_write(path: str | os.PathLike[str], write: Callable[[IO[bytes]], Any]) -> Path:
    """Write ``path`` through ``write(fh)`` on a temporary file beside it; whole or absent.

    The temporary file is fsync'ed, renamed over ``path`` and the folder fsync'ed. On any
    exception the temporary file is removed and ``path`` is untouched. Parent folders
    are created. Returns ``path``.
    """
    path = Path(path)
    folder = path.parent
    folder.mkdir(parents=True, exist_ok=True)
    remove_stale(folder, path.name)
    tmp = folder / temp_name(path.name, "tmp")
    # os.open with 0o666 lets the kernel apply the umask (mkstemp would force 0600).
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_BINARY", 0), 0o666)
    try:
        with os.fdopen(fd, "wb") as fh:
            write(fh)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    fsync_dir(folder)
    return path


def atomic_write_bytes(path: str | os.PathLike[str], data: bytes) -> Path:
    """:func:`atomic_write` of ``data``."""
    return atomic_write(path, lambda fh: fh.write(data))


def atomic_write_text(path: str | os.PathLike[str], text: str) -> Path:
    """:func:`atomic_write` of ``text`` as UTF-8."""
    return atomic_write_bytes(path, text.encode("utf-8"))


def save_figure(fig: Any, path: str | os.PathLike[str], dpi: int = 110) -> Path:
    """Save a matplotlib figure atomically (format from the suffix, PNG by default)."""
    return atomic_write_bytes(path, figure_bytes(fig, Path(path).suffix.lstrip(".") or "png", dpi))


def figure_bytes(fig: Any, format: str = "png", dpi: int = 110) -> bytes:
    """A matplotlib figure drawn in memory (what :func:`save_figure` writes)."""
    buf = io.BytesIO()
    fig.savefig(buf, format=format, dpi=dpi)
    return buf.getvalue()


# --------------------------------------------------------------------------- folders

_RENAME_EXCHANGE = 2  # linux/fs.h


def _exchange(a: Path, b: Path) -> bool:
    """Atomically swap two paths with renameat2(RENAME_EXCHANGE); False where unsupported."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        renameat2 = libc.renameat2
    except (OSError, AttributeError):
        return False
    at_fdcwd = -100
    rc = renameat2(at_fdcwd, os.fsencode(a), at_fdcwd, os.fsencode(b), _RENAME_EXCHANGE)
    if rc == 0:
        return True
    err = ctypes.get_errno()
    if err in (errno.ENOSYS, errno.EINVAL, errno.ENOTSUP, errno.EOPNOTSUPP):
        return False
    raise OSError(err, f"cannot swap {b} into place: {os.strerror(err)}", str(a))


def _fsync_tree(folder: Path) -> None:
    for root, _dirs, files in os.walk(folder):
        for f in files:
            fd = os.open(os.path.join(root, f), os.O_RDONLY)
            try:
                os.fsync(fd)
            finally:
                os.close(fd)
        fsync_dir(root)


def swap_in(staging: str | os.PathLike[str], dest: str | os.PathLike[str]) -> Path:
    """Put the folder ``staging`` at ``dest`` (same parent folder), replacing any old ``dest``.

    Everything in ``staging`` is fsync'ed first. With an old ``dest``, the two are
    exchanged atomically and the old one is deleted afterwards; a crash before the
    exchange leaves the old folder, after it the new one (plus a stale temporary that
    :func:`remove_stale` deletes). ``dest`` must be a folder or absent.
    """
    staging, dest = Path(staging), Path(dest)
    _fsync_tree(staging)
    if not dest.exists():
        os.rename(staging, dest)
    elif not dest.is_dir():
        raise NotADirectoryError(f"{dest} exists and is not a folder")
    elif _exchange(staging, dest):
        # ``staging`` now holds the old folder: give it a dead-writer-safe name first.
        old = dest.parent / temp_name(dest.name, "tmp")
        os.rename(staging, old)
        fsync_dir(dest.parent)
        shutil.rmtree(old, ignore_errors=True)
    else:
        old = dest.parent / temp_name(dest.name, "old")
        os.rename(dest, old)
        os.rename(staging, dest)
        fsync_dir(dest.parent)
        shutil.rmtree(old, ignore_errors=True)
    fsync_dir(dest.parent)
    return dest


@contextmanager
def staged_folder(dest: str | os.PathLike[str]) -> Iterator[Path]:
    """Yield an empty folder beside ``dest``; on a clean exit, :func:`swap_in` it at ``dest``.

    On an exception the staging folder is deleted and ``dest`` is untouched. The
    folder is created with the user's umask.
    """
    dest = Path(dest)
    dest.parent.mkdir(parents=True, exist_ok=True)
    remove_stale(dest.parent, dest.name)
    staging = dest.parent / temp_name(dest.name, "new")
    os.mkdir(staging)
    try:
        yield staging
        swap_in(staging, dest)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise


# --------------------------------------------------------------------------- locks

_HELD: dict[Path, tuple[int, int]] = {}  # lock path -> (fd, depth): re-entrant within a process


class OutputLock:
    """Exclusive advisory lock on an output path while a run writes it.

    ``with OutputLock(folder):`` holds ``flock`` on ``<parent>/.<name>.lock``. Another
    process asking for the same lock gets :class:`OutputBusyError` at once (no waiting);
    the same process may nest locks on one path. The lock file holds the owner's pid
    and is removed on release; one left by a killed run is unlocked and simply reused.
    """

    def __init__(self, path: str | os.PathLike[str]) -> None:
        # resolved: a folder reached through a symlink (its own, or a parent's) is locked as itself, so two runs
        # writing it by two names still exclude each other
        path = Path(path).resolve()
        self.path = path
        self.lock_file = path.parent / f".{path.name}.lock"

    def __enter__(self) -> OutputLock:
        key = self.lock_file
        if key in _HELD:
            fd, depth = _HELD[key]
            _HELD[key] = (fd, depth + 1)
            return self
        try:
            import fcntl
        except ImportError:  # not POSIX: no locking (documented limitation)
            _HELD[key] = (-1, 1)
            return self
        self.path.parent.mkdir(parents=True, exist_ok=True)
        while True:
            fd = os.open(key, os.O_RDWR | os.O_CREAT, 0o666)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                try:
                    owner = os.read(fd, 32).decode(errors="replace").strip() or "?"
                finally:
                    os.close(fd)
                raise OutputBusyError(
                    f"{self.path} is being written by another coassist run (pid {owner}); "
                    f"wait for it to finish (lock: {key})"
                ) from None
            # The previous holder unlinks the file when it lets go: if ours was unlinked
            # between our open and our flock, lock the new file instead.
            try:
                same = os.path.samestat(os.fstat(fd), os.stat(key))
            except FileNotFoundError:
                same = False
            if same:
                break
            os.close(fd)
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()}\n".encode())
        _HELD[key] = (fd, 1)
        return self

    def __exit__(self, *exc: object) -> None:
        fd, depth = _HELD[self.lock_file]
        if depth > 1:
            _HELD[self.lock_file] = (fd, depth - 1)
            return
        del _HELD[self.lock_file]
        if fd >= 0:
            # Unlink while still holding the lock (lockers check they hold the live file),
            # then close, which releases the flock. A killed run leaves the file unlocked.
            self.lock_file.unlink(missing_ok=True)
            os.close(fd)


# --------------------------------------------------------------------------- hashed JSON

#: The key of a hashed JSON file that holds the SHA-256 of the rest of it (module docstring).
HASH_KEY = "sha256"
#: The largest hashed JSON file read [bytes] unless the caller says otherwise (a calibration of
#: a hundred people is tens of kB).
MAX_HASHED_JSON_BYTES = 4 * 2**20


class HashedJsonError(CoassistError, ValueError):
    """A hashed JSON file that cannot be used (missing, malformed, another format, edited after it
    was written); ``str()`` is one line that names the file."""


def json_sha256(doc: Mapping[str, Any]) -> str:
    """SHA-256 (hex) of ``doc``'s canonical JSON: keys sorted, no spaces, ASCII, NaN and ±inf refused
    (ValueError). Equal for a document and its JSON round trip (a tuple hashes as the list it is read back as)."""
    text = json.dumps(doc, sort_keys=True, separators=(",", ":"), ensure_ascii=True, allow_nan=False)
    return hashlib.sha256(text.encode("ascii")).hexdigest()


def write_hashed_json(path: str | os.PathLike[str], doc: Mapping[str, Any], *, format: str) -> Path:
    """Write ``{"format": format, **doc, "sha256": …}`` to ``path`` atomically (:func:`atomic_write`); returns ``path``.

    ``doc`` : a JSON-ready mapping with string keys, without ``"format"`` or :data:`HASH_KEY`;
    its numbers finite (ValueError otherwise). The hash is that of the document as
    :func:`read_hashed_json` will parse it back.
    """
    if not isinstance(format, str) or not format:
        raise ValueError(f"format must be a non-empty string, got {format!r}")
    if not isinstance(doc, Mapping) or not all(isinstance(k, str) for k in doc):
        raise ValueError("a hashed JSON document must be a mapping with string keys")
    clash = sorted({"format", HASH_KEY} & set(doc))
    if clash:
        raise ValueError(
            f"a hashed JSON document may not hold {', '.join(map(repr, clash))}: write_hashed_json sets it"
        )
    content = json.loads(json.dumps({"format": format, **doc}, allow_nan=False))  # as it will be read back
    content[HASH_KEY] = json_sha256(content)
    return atomic_write_text(path, json.dumps(content, indent=1, allow_nan=False) + "\n")


def no_duplicate_keys(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    """A ``json.loads`` ``object_pairs_hook`` refusing a key given twice in one object (ValueError naming it):
    plain JSON keeps the last silently (a second ``"obstacle"`` list would replace the first)."""
    out: dict[str, Any] = {}
    for key, value in pairs:
        if key in out:
            raise ValueError(f"the key {key!r} appears twice")
        out[key] = value
    return out


def no_constant(name: str) -> Any:
    """A ``json.loads`` ``parse_constant`` refusing NaN and ±Infinity (ValueError naming it): JSON has no such
    numbers, Python's reader accepts them, and none of the project's files is written with them."""
    raise ValueError(f"{name} is not a number a file may hold")


def read_hashed_json(
    path: str | os.PathLike[str], *, format: str | tuple[str, ...], max_bytes: int = MAX_HASHED_JSON_BYTES
) -> dict[str, Any]:
    """The document :func:`write_hashed_json` wrote at ``path``, without ``"format"`` and :data:`HASH_KEY`.

    ``format``: the format the file must be, or a tuple of those accepted (the current first, then older ones a
    reader still takes; the caller reads which one it is from the fields).

    :class:`HashedJsonError` (one line naming the file) when the file is missing or unreadable,
    larger than ``max_bytes``, not UTF-8 JSON (NaN, Infinity, a key given twice, nesting too deep
    included), not an object, of another ``format``, without its hash, or when its content does
    not match its hash (edited after it was written). What the fields mean is the caller's to check.
    """
    path = Path(path)
    formats = (format,) if isinstance(format, str) else tuple(format)
    if not formats or not all(isinstance(f, str) and f for f in formats):
        raise ValueError(f"read_hashed_json: format must be a name or a tuple of names, got {format!r}")
    format = formats[0]

    def fail(what: str) -> HashedJsonError:
        return HashedJsonError(f"{path}: {what}")

    try:
        if path.stat().st_size > max_bytes:
            raise fail(f"larger than {max_bytes} bytes: not a {format} file")
        raw = path.read_bytes()
    except FileNotFoundError:
        raise fail("not found") from None
    except OSError as exc:
        raise fail(f"cannot be read: {exc.strerror}") from None
    try:
        doc = json.loads(raw.decode("utf-8"), object_pairs_hook=no_duplicate_keys, parse_constant=no_constant)
    except RecursionError:
        raise fail("JSON nested too deeply") from None
    except UnicodeDecodeError as exc:
        raise fail(f"not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    except ValueError as exc:  # json.JSONDecodeError is one; so are the hooks' refusals
        raise fail(f"malformed JSON: {exc}") from None
    if not isinstance(doc, dict):
        raise fail(f"must hold a JSON object, got {type(doc).__name__}")
    if doc.get("format") not in formats:
        raise fail(f"format {doc.get('format')!r}, expected {' or '.join(repr(f) for f in formats)}")
    recorded = doc.pop(HASH_KEY, None)
    if recorded is None:
        raise fail(
            f"carries no {HASH_KEY!r} (written before coassist hashed these files, or by hand): "
            "it cannot be verified; write it again with coassist"
        )
    if recorded != json_sha256(doc):
        raise fail(
            f"its content does not match its {HASH_KEY!r} (edited after it was written?): "
            "restore it or write it again with coassist"
        )
    del doc["format"]
    return doc


def json_object_with(path: str | os.PathLike[str], keys: Iterable[str], max_bytes: int = 64 * 2**20) -> bool:
    """Whether ``path`` holds a JSON object with every one of ``keys`` (a file a command wrote and may replace: an
    earlier result of its own); False for anything else, a file over ``max_bytes`` or one that cannot be read."""
    try:
        if os.stat(path).st_size > max_bytes:
            return False
        with open(path, "rb") as fh:
            doc = json.loads(fh.read())
    except (OSError, ValueError):
        return False
    return isinstance(doc, dict) and set(keys) <= set(doc)
