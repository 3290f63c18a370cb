"""Run an untrusted engine once, bounded in time and output, and end its whole process tree.

An engine is someone else's program. It may start background children, daemonise them
(``setsid``), hold our pipes open from a grandchild, or print gigabytes. :func:`run_engine`

- starts it in a new session (its own process group), stdin closed;
- reads stdout and stderr in two threads that keep the first :data:`HEAD_BYTES` and the last
  :data:`TAIL_BYTES` of each and drain the rest, so memory stays bounded whatever it prints;
- waits for the *engine* to exit (never for the pipes: a grandchild may hold them for ever), at
  most ``timeout`` seconds, then ends every process it started, on success as on failure.

How the tree is found. A process group is not enough: ``setsid`` leaves it. A fresh cgroup
would contain everything, but needs a writable cgroup hierarchy, which an ordinary user or a
container rarely has. So two marks are used together, both available to an unprivileged
process on Linux:

1. the engine's environment carries a random token (:data:`MARK`), inherited by every
   descendant that does not scrub its environment; ``/proc/<pid>/environ`` shows it;
2. while an engine runs, this process is a *child subreaper* (``prctl(PR_SET_CHILD_SUBREAPER)``):
   a descendant whose parent exits (the classic double fork of a daemon) is re-parented to us
   rather than to init, so it stays findable by its parent id even with a scrubbed environment.

After the engine exits (or at the time limit) every process in the engine's group or session,
carrying the token, or adopted by us while it ran (our children from before are spared), and
all of their descendants, are sent SIGKILL, repeatedly until a scan of /proc finds none;
adopted ones are reaped. Elsewhere
than Linux only the process group is killed. This bounds the processes, not what they do while
they run: it is not a sandbox (docs/checking.md, "Threat model").
"""

from __future__ import annotations

import ctypes
import os
import secrets
import select
import signal
import subprocess
import threading
import time
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Dict, Iterator, List, Optional, Sequence, Set, Tuple

__all__ = [
    "EngineRun",
    "run_engine",
    "end_process_tree",
    "head_and_tail",
    "dropped_marker",
    "MARK",
    "HEAD_BYTES",
    "TAIL_BYTES",
]

MARK = "MJED_VERIFY_ENGINE_RUN"  # environment variable carrying the run's token
HEAD_BYTES = 64 << 10  # kept from the start of each stream
TAIL_BYTES = 1 << 20  # kept from its end; everything between is read and dropped
_PR_SET_CHILD_SUBREAPER = 36


@dataclass(frozen=True)
class EngineRun:
    """What one run of the engine gave.

    returncode: the engine's exit status (negative: killed by that signal).
    timed_out: it was still running at the time limit (then killed).
    stdout, stderr: head and tail of each stream (``...[N bytes dropped]...`` between).
    ended: how many other processes of its tree were still alive afterwards and were killed.
    """

    returncode: int
    timed_out: bool
    stdout: bytes
    stderr: bytes
    ended: int


def dropped_marker(dropped: int) -> bytes:
    """What stands between a stream's kept head and tail when ``dropped`` bytes were left out."""
    return f"\n...[{dropped} bytes dropped]...\n".encode() if dropped else b""


def head_and_tail(data: bytes) -> bytes:
    """A whole stream ``data`` as :func:`run_engine` keeps one: its first HEAD_BYTES and last
    TAIL_BYTES, the bytes between said dropped.
    """
    if len(data) <= HEAD_BYTES + TAIL_BYTES:
        return data
    dropped = len(data) - HEAD_BYTES - TAIL_BYTES
    return data[:HEAD_BYTES] + dropped_marker(dropped) + data[-TAIL_BYTES:]


class _BoundedReader(threading.Thread):
    """Drain one pipe, keeping its head and tail. It polls, so it can be told to stop even while
    a process that escaped every kill still holds the pipe open.
    """

    def __init__(self, fd: int) -> None:
        super().__init__(daemon=True)
        self.fd = fd
        self.head = bytearray()
        self.tail = bytearray()
        self.dropped = 0
        self.stop = threading.Event()

    def run(self) -> None:
        poller = select.poll()  # not select(): it fails on descriptors past FD_SETSIZE
        poller.register(self.fd, select.POLLIN | select.POLLHUP | select.POLLERR)
        try:
            while not self.stop.is_set():
                if not poller.poll(100):
                    continue
                chunk = os.read(self.fd, 1 << 16)
                if not chunk:
                    return
                room = HEAD_BYTES - len(self.head)
                if room > 0:
                    self.head += chunk[:room]
                    chunk = chunk[room:]
                self.tail += chunk
                if len(self.tail) > TAIL_BYTES:
                    cut = len(self.tail) - TAIL_BYTES
                    self.dropped += cut
                    del self.tail[:cut]
        except OSError:
            return

    def text(self) -> bytes:
        return bytes(self.head) + dropped_marker(self.dropped) + bytes(self.tail)


def _subreaper(on: bool) -> bool:
    """Make this process a child subreaper (Linux); False where that is not possible."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        return libc.prctl(_PR_SET_CHILD_SUBREAPER, 1 if on else 0, 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False


@contextmanager
def _adopting() -> Iterator[bool]:
    # Only while an engine runs: outside, orphans of unrelated work go to init as usual.
    was = ctypes.c_int(0)
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        if libc.prctl(37, ctypes.byref(was), 0, 0, 0) != 0:  # PR_GET_CHILD_SUBREAPER
            was = ctypes.c_int(0)
    except (OSError, AttributeError):
        pass
    ok = _subreaper(True)
    try:
        yield ok
    finally:
        if ok and not was.value:
            _subreaper(False)


def _proc_table() -> Dict[int, Tuple[int, int, int, str]]:
    """Pid -> (ppid, pgid, sid, state) of every process visible in /proc."""
    table = {}
    try:
        names = os.listdir("/proc")
    except OSError:
        return table
    for name in names:
        if not name.isdigit():
            continue
        try:
            with open(f"/proc/{name}/stat", "rb") as fh:
                raw = fh.read()
        except OSError:
            continue
        rest = raw[raw.rfind(b")") + 2 :].split()  # the command name may hold spaces and ')'
        try:
            table[int(name)] = (int(rest[1]), int(rest[2]), int(rest[3]), rest[0].decode())
        except (IndexError, ValueError):
            continue
    return table


def _carries(pid: int, token: bytes) -> bool:
    try:
        with open(f"/proc/{pid}/environ", "rb") as fh:
            return token in fh.read().split(b"\0")
    except OSError:  # gone, or another user's: not ours to kill
        return False


def _tree(root: int, token: bytes, me: int, spare: Set[int]) -> Set[int]:
    """Live processes of the engine's tree, by the rules of the module docstring.

    spare: our own children from before the engine started (an MPI runtime, for one, keeps a
    helper in its own session as our child: killing it would abort this process).
    """
    table = _proc_table()
    found = {
        pid
        for pid, (ppid, pgid, sid, state) in table.items()
        if pid != me
        and pid not in spare
        and state != "Z"
        and (pgid == root or sid == root or (ppid == me and pid != root) or _carries(pid, token))
    }
    children: Dict[int, List[int]] = {}
    for pid, (ppid, *_rest) in table.items():
        children.setdefault(ppid, []).append(pid)
    stack = list(found)
    while stack:  # and their descendants, whatever their session or environment
        for child in children.get(stack.pop(), []):
            if child not in found and child != me and child not in spare and table[child][3] != "Z":
                found.add(child)
                stack.append(child)
    return found


def _children(me: int) -> Set[int]:
    return {pid for pid, (ppid, *_rest) in _proc_table().items() if ppid == me}


def _reap_adopted(me: int, skip: Set[int]) -> None:
    """Collect the exit status of adopted children that died (else they stay as zombies)."""
    for pid, (ppid, *_rest) in _proc_table().items():
        if ppid == me and pid not in skip:
            try:
                os.waitpid(pid, os.WNOHANG)
            except ChildProcessError:
                pass


def end_process_tree(
    root: Optional[int], token: str, spare: Set[int] = frozenset(), *, rounds: int = 200
) -> int:
    """SIGKILL the engine's process group and every process of its tree; returns how many
    distinct processes were killed (the group leader not counted). spare: as for _tree.

    root None: the engine's pid is not known (an interrupt arrived while it was being started,
    after the fork); its tree is then found by the token and by being our new child.
    """
    if root is not None:
        try:
            os.killpg(root, signal.SIGKILL)
        except (ProcessLookupError, PermissionError):
            pass
    me, mark = os.getpid(), f"{MARK}={token}".encode()
    # -1 matches no process group or session: only the token and our parentage find the tree
    group = -1 if root is None else root
    killed: Set[int] = set()
    for _ in range(rounds):  # a forking process may add children between two scans
        live = _tree(group, mark, me, spare) - {group}
        if not live:
            break
        for pid in live:
            try:
                os.kill(pid, signal.SIGKILL)
            except (ProcessLookupError, PermissionError):
                pass
        killed |= live
        time.sleep(0.005)
        _reap_adopted(me, spare | {group})
    _reap_adopted(me, spare | {group})
    return len(killed)


def run_engine(
    argv: Sequence[str], timeout: float, *, env: Optional[Dict[str, str]] = None
) -> EngineRun:
    """Run ``argv`` (no shell) with a time limit; its whole tree is ended before returning.

    Raises OSError when it cannot be started. An interrupt (Ctrl-C, or SIGTERM turned into one)
    arriving at any point after the fork, even before the engine's pid is known here, still
    ends the tree before it propagates.
    """
    token = secrets.token_hex(16)
    env = dict(os.environ if env is None else env)
    env[MARK] = token
    spare = _children(os.getpid())
    proc: Optional[subprocess.Popen] = None
    readers: List[_BoundedReader] = []
    fds: List[int] = []
    timed_out, ended = False, 0
    with _adopting():
        out_r, out_w = os.pipe()
        err_r, err_w = os.pipe()
        fds += [out_r, err_r]
        try:
            try:
                proc = subprocess.Popen(
                    list(argv),
                    stdin=subprocess.DEVNULL,
                    stdout=out_w,
                    stderr=err_w,
                    start_new_session=True,
                    env=env,
                    close_fds=True,
                )
            finally:
                os.close(out_w)
                os.close(err_w)
            readers = [_BoundedReader(out_r), _BoundedReader(err_r)]
            for r in readers:
                r.start()
            try:
                proc.wait(timeout=timeout)
            except subprocess.TimeoutExpired:
                timed_out = True
        finally:  # also on Ctrl-C, wherever it lands after the fork; a failed start finds none
            try:
                ended = end_process_tree(None if proc is None else proc.pid, token, spare)
                if proc is not None:
                    proc.wait()
            finally:
                # every writer is dead now; one out of our reach (another user's) cannot hold us
                for r in readers:
                    if r.ident is None:  # interrupted before it started
                        continue
                    r.join(timeout=2.0)
                    r.stop.set()
                    r.join()
                for fd in fds:
                    os.close(fd)
    return EngineRun(proc.returncode, timed_out, readers[0].text(), readers[1].text(), ended)
