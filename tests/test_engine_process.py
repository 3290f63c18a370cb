"""An engine is untrusted code: --timeout bounds the run, its whole process tree (daemonised or
not) is ended after every case, and its output is read through bounded buffers.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time

import pytest

from conformance.engine.process import HEAD_BYTES, TAIL_BYTES, run_engine

linux_only = pytest.mark.skipif(
    not os.path.isdir("/proc/self"), reason="the process scan reads /proc"
)


def _alive(pid: int) -> bool:
    """Running, not a zombie waiting for its parent."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as fh:
            raw = fh.read()
    except OSError:
        return False
    return raw[raw.rfind(b")") + 2 :].split()[0] != b"Z"


def _pids(path) -> list:
    deadline = time.monotonic() + 5
    while time.monotonic() < deadline and not os.path.exists(path):
        time.sleep(0.02)
    return [int(p) for p in open(path).read().split()]


def _assert_ended(path, count: int) -> None:
    """The processes that wrote their pid into ``path`` (``count`` of them) are all gone."""
    pids = _pids(path)
    assert len(pids) == count
    # A killed process needs a moment to become a zombie on a loaded machine: poll, do not
    # guess one sleep; one still running after 5 s was not ended.
    deadline = time.monotonic() + 5
    while [p for p in pids if _alive(p)] and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not [p for p in pids if _alive(p)]


@linux_only
def test_a_daemonised_grandchild_holding_stderr_does_not_hold_the_run(tmp_path):
    pidfile = tmp_path / "pids"
    script = (
        f"setsid sh -c 'echo $$ >> {pidfile}; exec sleep 45' & echo done >&2; sleep 0.3; exit 0"
    )
    t0 = time.monotonic()
    ran = run_engine(["sh", "-c", script], timeout=20)
    assert time.monotonic() - t0 < 5
    assert ran.returncode == 0 and not ran.timed_out and b"done" in ran.stderr
    _assert_ended(pidfile, 1)
    assert ran.ended >= 1


@linux_only
def test_the_time_limit_holds_against_a_grandchild_that_never_exits(tmp_path):
    pidfile = tmp_path / "pids"
    script = f"setsid sh -c 'echo $$ >> {pidfile}; exec sleep 600' & sleep 600"
    t0 = time.monotonic()
    ran = run_engine(["sh", "-c", script], timeout=1.0)
    assert time.monotonic() - t0 < 5
    assert ran.timed_out
    _assert_ended(pidfile, 1)


@linux_only
def test_a_double_forked_daemon_with_a_scrubbed_environment_is_ended(tmp_path):
    # The daemon leaves the session, drops the marked environment and is orphaned by its parent:
    # only the subreaper keeps it findable.
    pidfile = tmp_path / "pids"
    daemon = (
        f"env -i setsid sh -c 'echo $$ >> {pidfile}; exec sleep 45' </dev/null >/dev/null 2>&1 &"
    )
    ran = run_engine(["sh", "-c", f'sh -c "{daemon}"; sleep 0.3; exit 0'], timeout=20)
    assert ran.returncode == 0
    _assert_ended(pidfile, 1)


@linux_only
def test_background_children_of_a_successful_engine_are_not_left_running(tmp_path):
    pidfile = tmp_path / "pids"
    children = "; ".join(f"(sh -c 'echo $$ >> {pidfile}; exec sleep 45' &)" for _ in range(5))
    ran = run_engine(["sh", "-c", f"{children}; sleep 0.3; exit 0"], timeout=20)
    assert ran.returncode == 0
    _assert_ended(pidfile, 5)


def test_output_is_kept_as_head_and_tail_only(tmp_path):
    # 64 MB on stderr and stdout: the run keeps at most head + tail of each
    writer = (
        "import sys\nchunk = b'x' * (1 << 20)\nsys.stderr.buffer.write(b'FIRST')\n"
        "for _ in range(64):\n"
        "    sys.stderr.buffer.write(chunk); sys.stdout.buffer.write(chunk)\n"
        "sys.stderr.buffer.write(b'LAST')\n"
    )
    ran = run_engine([sys.executable, "-c", writer], timeout=60)
    assert ran.returncode == 0
    for stream in (ran.stderr, ran.stdout):
        assert len(stream) <= HEAD_BYTES + TAIL_BYTES + 100
        assert b"bytes dropped" in stream
    assert ran.stderr.startswith(b"FIRST") and ran.stderr.endswith(b"LAST")


def test_an_engine_that_cannot_start_raises_oserror(tmp_path):
    with pytest.raises(OSError):
        run_engine([str(tmp_path / "missing-engine")], timeout=5)


@linux_only
@pytest.mark.oracle
def test_check_timeout_bounds_a_correct_engine_with_a_detached_grandchild(tmp_path, capsys):
    from comparisons.cli import main
    from reference_fem import dolfinx_available

    if not dolfinx_available():
        pytest.skip("check needs the oracle (python3-dolfinx)")
    engine = os.path.join(os.path.dirname(__file__), "engines", "mjed_engine.py")
    pidfile = tmp_path / "pids"
    # a correct engine that leaves a daemon holding its stderr for 45 s
    cmd = (
        f'sh -c \'setsid sh -c "echo \\$\\$ >> {pidfile}; exec sleep 45" & '
        f'exec {sys.executable} {engine} "$0" "$1"\' {{input}} {{output}}'
    )
    t0 = time.monotonic()
    code = main(
        [
            "check",
            "--command",
            cmd,
            "--material",
            "NeoHookean",
            "--states",
            "rest",
            "--timeout",
            "5",
            "--quiet",
            "--out",
            str(tmp_path / "out"),
        ]
    )
    elapsed = time.monotonic() - t0
    assert code == 0, capsys.readouterr()
    assert elapsed < 30  # before: 46 s per process, and the case called "ran past the time limit"
    _assert_ended(pidfile, 5)  # one daemon for the case, one for each of its four probes
    (run,) = os.listdir(tmp_path / "out")
    assert json.load(open(tmp_path / "out" / run / "results.json"))["exit_code"] == 0


@linux_only
def test_sigterm_to_check_ends_the_engine_it_is_running(tmp_path):
    import signal
    import subprocess

    pidfile = tmp_path / "pids"
    engine = f"sh -c 'echo $$ >> {pidfile}; exec sleep 60' {{input}} {{output}}"
    argv = [
        sys.executable,
        "-m",
        "comparisons.cli",
        "check",
        "--command",
        engine,
        "--material",
        "NeoHookean",
        "--states",
        "rest",
        "--out",
        str(tmp_path / "out"),
    ]
    proc = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    # The check compiles its oracle forms before it starts the engine; from empty JIT caches,
    # beside another test worker compiling, that took more than a minute. Wait on the engine's
    # own start (its pid written, not only the file created: a signal between the two would
    # leave no pid) for as long as the check is alive, with a bound that only a hang reaches.
    deadline = time.monotonic() + 600
    while (
        time.monotonic() < deadline
        and proc.poll() is None
        and not (pidfile.exists() and pidfile.read_text().strip())
    ):
        time.sleep(0.05)
    assert proc.poll() is None, f"the check ended before its engine started: {proc.stderr.read()}"
    assert pidfile.exists(), "the engine did not start within 600 s"
    proc.send_signal(signal.SIGTERM)
    assert proc.wait(timeout=30) == 130
    assert "interrupted" in proc.stderr.read()
    _assert_ended(pidfile, 1)


@linux_only
@pytest.mark.parametrize("where", ["reader start", "engine start"])
def test_an_interrupt_while_the_engine_is_being_started_still_ends_it(tmp_path, monkeypatch, where):
    # SIGTERM becomes KeyboardInterrupt wherever the main thread is. It once landed after the
    # fork but before the cleanup was armed (CI, 27 Nov 2026): the engine outlived the check.
    from conformance.engine import process

    pidfile = tmp_path / "pids"
    script = f"echo $$ >> {pidfile}; exec sleep 60"

    def wait_for_engine_then_interrupt(*_args, **_kwargs):
        _pids(pidfile)  # the engine is running: its pid is written
        raise KeyboardInterrupt()

    if where == "reader start":
        monkeypatch.setattr(process._BoundedReader, "start", wait_for_engine_then_interrupt)
    else:  # after the fork, before Popen returns: the engine's pid is not known here yet
        real = subprocess.Popen.__init__

        def popen_then_interrupt(self, *args, **kwargs):
            real(self, *args, **kwargs)
            wait_for_engine_then_interrupt()

        monkeypatch.setattr(subprocess.Popen, "__init__", popen_then_interrupt)
    with pytest.raises(KeyboardInterrupt):
        run_engine(["sh", "-c", script], timeout=20)
    _assert_ended(pidfile, 1)
