"""Reading files of an untrusted kit or engine output: confined, regular, bounded.

A kit comes from someone else (downloaded with a paper, attached to a bug report) and an
engine's output directory is written by someone else's program. Every file ``check`` reads
from them goes through :func:`read_confined`, which

- refuses a name that is absolute or climbs with ``..`` and a path whose real location
  (symbolic links followed) leaves the directory it belongs to;
- opens without blocking and refuses what is not a regular file, by its kind (a directory, a
  FIFO, a device, a socket), so that a FIFO cannot hang the check nor /dev/zero fill memory;
- compares the size, taken from the open file, with what the caller expects or allows
  *before* reading, and reads that many bytes at most.

Case ids become directory and file names, so they are checked by :func:`check_case_id`.
"""

from __future__ import annotations

import hashlib
import os
import re
import stat
from typing import Optional

__all__ = [
    "ConfinementError",
    "check_case_id",
    "confined_path",
    "read_confined",
    "CASE_ID_PATTERN",
    "MAX_CASE_ID",
]

#: Letters, digits and ``_ . + - ~``; not starting with a dot and without ``..``, so that an id
#: is one harmless path component (docs/conventions.md, "The kit manifest").
CASE_ID_PATTERN = re.compile(r"[A-Za-z0-9_+~-][A-Za-z0-9_.+~-]*")
MAX_CASE_ID = 200  # leaves room for suffixes such as ".vtu" within a 255-byte file name


class ConfinementError(ValueError):
    """A path or name of an untrusted file that cannot be used; the message names it."""


def check_case_id(cid: object, where: str) -> str:
    """The id itself, or ConfinementError saying why it cannot name a directory."""
    if not isinstance(cid, str):
        raise ConfinementError(f"{where}: case id must be a string, got {type(cid).__name__}")
    shown = cid if len(cid) <= 80 else cid[:77] + "..."
    if len(cid) > MAX_CASE_ID:
        raise ConfinementError(
            f"{where}: case id {shown!r} is longer than {MAX_CASE_ID} characters"
        )
    if not CASE_ID_PATTERN.fullmatch(cid) or ".." in cid:
        raise ConfinementError(
            f"{where}: case id {shown!r} is not a safe name (letters, digits "
            "and _ . + - ~ only, not starting with '.', no '..', no path "
            "separators)"
        )
    return cid


def confined_path(root: str, rel: object, what: str) -> str:
    """``root/rel`` for a relative ``rel`` that stays inside ``root`` once links are followed.

    what: how to name ``rel`` in a message (e.g. "case X: manifest.json: field 'input'").
    """
    if not isinstance(rel, str) or not rel:
        raise ConfinementError(f"{what}: expected a non-empty path relative to {root}, got {rel!r}")
    if "\x00" in rel:
        raise ConfinementError(f"{what}: {rel!r} (in {root}) contains a NUL character")
    if os.path.isabs(rel):
        raise ConfinementError(
            f"{what}: {rel!r} (in {root}) is an absolute path; paths in a kit are relative to it"
        )
    parts = rel.replace("\\", "/").split("/")
    if ".." in parts:
        raise ConfinementError(
            f"{what}: {rel!r} (in {root}) climbs out with '..'; paths in a kit stay inside it"
        )
    path = os.path.join(root, rel)
    real_root = os.path.realpath(root)
    real = os.path.realpath(path)
    if real != real_root and os.path.commonpath([real, real_root]) != real_root:
        raise ConfinementError(
            f"{what}: {path} leads outside {root} (a symbolic link to {real}); "
            "refused: only files inside it are read"
        )
    return path


def _kind(mode: int) -> Optional[str]:
    for test, name in (
        (stat.S_ISDIR, "a directory"),
        (stat.S_ISFIFO, "a FIFO (named pipe)"),
        (stat.S_ISCHR, "a character device"),
        (stat.S_ISBLK, "a block device"),
        (stat.S_ISSOCK, "a socket"),
    ):
        if test(mode):
            return name
    return None if stat.S_ISREG(mode) else "not a regular file"


def read_confined(
    root: str,
    rel: str,
    what: str,
    *,
    limit: int,
    expected: Optional[int] = None,
    sha256: Optional[str] = None,
    missing: str = "",
) -> bytearray:
    """The bytes of the regular file ``root/rel``, at most ``limit`` of them.

    expected: the exact size the caller needs (the message gives both sizes otherwise).
    sha256: the digest the bytes must have (checked on the very bytes returned).
    missing: appended to the "file missing" message (what the file should hold).
    Raises ConfinementError naming the file for each refusal.
    """
    path = confined_path(root, rel, what)
    flags = os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_NOCTTY", 0) | getattr(os, "O_CLOEXEC", 0)
    try:
        fd = os.open(path, flags)
    except FileNotFoundError:
        raise ConfinementError(f"{what}: {path}: file missing{missing}") from None
    except OSError as exc:
        raise ConfinementError(
            f"{what}: {path}: cannot be opened ({exc.strerror or exc})"
        ) from None
    try:
        st = os.fstat(fd)
        kind = _kind(st.st_mode)
        if kind is not None:
            raise ConfinementError(f"{what}: {path}: is {kind}, not a regular file")
        size = st.st_size
        if expected is not None and size != expected:
            raise ConfinementError(f"{what}: {path}: {size} bytes, expected {expected}")
        if size > limit:
            raise ConfinementError(
                f"{what}: {path}: {size} bytes, more than the {limit} this file may hold"
            )
        buf = bytearray(size)
        view, got = memoryview(buf), 0
        while got < size:
            n = os.readv(fd, [view[got:]])
            if n == 0:
                break
            got += n
        if got != size or os.read(fd, 1):  # the file changed while it was read
            raise ConfinementError(f"{what}: {path}: changed size while being read")
    finally:
        os.close(fd)
    if sha256 is not None and hashlib.sha256(buf).hexdigest() != sha256:
        raise ConfinementError(
            f"{what}: {path}: changed since export (SHA-256 differs); re-export the kit"
        )
    return buf
