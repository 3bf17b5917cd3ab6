"""What ``-o PATH`` does to the file system, and what a points file may contain.

Checked against the file system itself (``os.lstat``: file type, permission bits, link
targets, folder listings before and after), not against our own code: regular files are
replaced by rename and keep their mode, new files get 0666 minus the umask, devices and FIFOs
are written in place, links are followed, directories refused (exit 3), nothing else in the
folder is touched, and SIGTERM/SIGHUP/SIGINT during ``run`` leave no temporary file.
"""

from __future__ import annotations

import contextlib
import json
import os
import signal
import stat
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from nurbscnc.cli.main import main
from nurbscnc.errors import DataError, OutputError
from nurbscnc.output.files import POINT_COLUMNS, atomic_output, read_points

ROOT = Path(__file__).resolve().parents[1]
NACA = ROOT / "programs" / "naca2415.nc"
#: A short program: 10 mm at 600 mm/min, about 1000 reference points.
SHORT = "G21 G90 G0 X0 Y0\nG1 X10 F600\nM2\n"


def run(args, **kwargs):
    return CliRunner().invoke(main, [str(a) for a in args], **kwargs)


@pytest.fixture
def program(tmp_path):
    path = tmp_path / "src" / "part.nc"
    path.parent.mkdir()
    path.write_text(SHORT, encoding="ascii")
    return path


def listing(folder: Path) -> dict:
    """Name → (file type and mode, size, link target) of everything in ``folder``."""
    entries = {}
    for name in sorted(os.listdir(folder)):
        st = os.lstat(folder / name)
        link = os.readlink(folder / name) if stat.S_ISLNK(st.st_mode) else None
        entries[name] = (st.st_mode, st.st_size if stat.S_ISREG(st.st_mode) else None, link)
    return entries


def points_rows(path: Path) -> int:
    lines = path.read_text(encoding="ascii").splitlines()
    assert lines[0] == ",".join(POINT_COLUMNS)
    return len(lines) - 1


# ------------------------------------------------------------------------------ regular files


def test_new_file_gets_0666_minus_umask(tmp_path, program):
    target = tmp_path / "new.csv"
    old = os.umask(0o027)
    try:
        result = run(["run", program, "-o", target])
    finally:
        os.umask(old)
    assert result.exit_code == 0, result.output
    assert stat.S_IMODE(os.stat(target).st_mode) == 0o640  # 0666 & ~0027
    assert points_rows(target) > 900


@pytest.mark.parametrize("mode", [0o644, 0o664, 0o600, 0o755])
def test_existing_file_keeps_its_mode(tmp_path, program, mode):
    target = tmp_path / "points.csv"
    target.write_text("old\n")
    os.chmod(target, mode)
    inode = os.stat(target).st_ino
    result = run(["run", program, "-o", target])
    assert result.exit_code == 0, result.output
    st = os.stat(target)
    assert stat.S_IMODE(st.st_mode) == mode
    assert st.st_ino != inode  # replaced by rename, not rewritten in place
    assert points_rows(target) > 900


def test_only_the_output_is_touched(tmp_path, program):
    folder = tmp_path / "out"
    folder.mkdir()
    (folder / "other.txt").write_text("keep")
    (folder / "points.csv").write_text("old")
    before = listing(folder)
    result = run(["run", program, "-o", folder / "points.csv"])
    assert result.exit_code == 0, result.output
    after = listing(folder)
    assert set(after) == set(before)  # no temporary file left, nothing new
    assert after["other.txt"] == before["other.txt"]
    assert (folder / "other.txt").read_text() == "keep"


def test_failed_write_keeps_the_old_file_and_leaves_no_temp(tmp_path, monkeypatch):
    target = tmp_path / "keep.csv"
    target.write_text("precious\n")

    class Boom(RuntimeError):
        pass

    with pytest.raises(Boom), atomic_output(str(target)) as fh:
        fh.write("half")
        raise Boom
    assert target.read_text() == "precious\n"
    assert sorted(os.listdir(tmp_path)) == ["keep.csv"]


# --------------------------------------------------------------- devices, FIFOs, directories


def _char_device(tmp_path) -> Path:
    """A character device to write to: a private copy of /dev/null (mknod, as root), else
    /dev/null itself when we cannot replace it (not root: rename into /dev is refused)."""
    node = tmp_path / "null"
    try:
        os.mknod(node, stat.S_IFCHR | 0o666, os.makedev(1, 3))
        return node
    except (PermissionError, OSError):
        if os.geteuid() == 0:  # root without CAP_MKNOD: never risk the real /dev/null
            pytest.skip("cannot create a device node, and /dev/null must not be risked as root")
        return Path("/dev/null")


def test_character_device_is_written_in_place(tmp_path, program):
    device = _char_device(tmp_path)
    before = os.lstat(device)
    result = run(["run", program, "-o", device])
    assert result.exit_code == 0, result.output
    after = os.lstat(device)
    assert stat.S_ISCHR(after.st_mode)
    assert (after.st_ino, after.st_rdev) == (before.st_ino, before.st_rdev)
    assert not [n for n in os.listdir(device.parent) if n.startswith(".nurbscnc-")]


def test_fifo_is_written_in_place(tmp_path, program):
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    received = []

    def reader():
        with open(fifo, "rb") as fh:
            received.append(fh.read())

    thread = threading.Thread(target=reader, daemon=True)
    thread.start()
    result = run(["run", program, "-o", fifo])
    if thread.is_alive():  # unblock the reader if nothing opened the FIFO for writing
        # Non-blocking: the reader may be ending just now, and a blocking open for writing
        # would then wait for ever for a reader (ENXIO: no reader has it open any more).
        with contextlib.suppress(OSError):
            os.close(os.open(fifo, os.O_WRONLY | os.O_NONBLOCK))
    thread.join(10)
    assert result.exit_code == 0, result.output
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode)
    text = received[0].decode("ascii").splitlines()
    assert text[0] == ",".join(POINT_COLUMNS) and len(text) > 900
    assert sorted(os.listdir(tmp_path)) == ["pipe", "src"]


def test_output_directory_exits_3(tmp_path, program):
    folder = tmp_path / "adir"
    folder.mkdir()
    result = run(["run", program, "-o", folder])
    assert result.exit_code == 3, result.output
    assert f"cannot write {folder}: it is a directory" in result.stderr
    assert os.listdir(folder) == []


def test_missing_folder_exits_3(tmp_path, program):
    result = run(["run", program, "-o", tmp_path / "nope" / "x.csv"])
    assert result.exit_code == 3
    assert "does not exist" in result.stderr


@pytest.mark.skipif(os.geteuid() == 0, reason="root may write a read-only file")
def test_read_only_file_is_refused(tmp_path, program):
    target = tmp_path / "ro.csv"
    target.write_text("old")
    os.chmod(target, 0o444)
    result = run(["run", program, "-o", target])
    assert result.exit_code == 3
    assert target.read_text() == "old"


def test_read_only_existing_file_is_refused_by_access_check(tmp_path, monkeypatch):
    """Even as root (where the kernel would allow it) the W_OK check is what decides."""
    target = tmp_path / "ro.csv"
    target.write_text("old")
    monkeypatch.setattr(os, "access", lambda path, mode: False)
    with pytest.raises(OutputError, match="Permission denied"), atomic_output(str(target)):
        pass
    assert target.read_text() == "old"


# ------------------------------------------------------------------------------- symlinks


def test_symlink_is_followed_and_kept(tmp_path, program):
    real_dir = tmp_path / "real"
    real_dir.mkdir()
    real = real_dir / "points.csv"
    real.write_text("old")
    os.chmod(real, 0o640)
    link = tmp_path / "link.csv"
    link.symlink_to(real)
    result = run(["run", program, "-o", link])
    assert result.exit_code == 0, result.output
    assert link.is_symlink() and os.readlink(link) == str(real)
    assert stat.S_IMODE(os.stat(real).st_mode) == 0o640
    assert points_rows(real) > 900
    # the temporary file went to the target's folder and is gone from both
    assert sorted(os.listdir(real_dir)) == ["points.csv"]
    assert sorted(os.listdir(tmp_path)) == ["link.csv", "real", "src"]


def test_dangling_symlink_creates_its_target(tmp_path, program):
    link = tmp_path / "link.csv"
    link.symlink_to(tmp_path / "made.csv")
    result = run(["run", program, "-o", link])
    assert result.exit_code == 0, result.output
    assert link.is_symlink()
    assert points_rows(tmp_path / "made.csv") > 900


def test_symlink_to_a_directory_exits_3(tmp_path, program):
    (tmp_path / "d").mkdir()
    (tmp_path / "l").symlink_to(tmp_path / "d")
    result = run(["run", program, "-o", tmp_path / "l"])
    assert result.exit_code == 3
    assert os.listdir(tmp_path / "d") == []


# ------------------------------------------------------------------------------- batch


def test_batch_with_one_stem_twice_refuses_naming_both(tmp_path):
    for sub in ("a", "b"):
        (tmp_path / sub).mkdir()
        (tmp_path / sub / "x.nc").write_text(SHORT)
    out = tmp_path / "out"
    result = run(
        [
            "run",
            "--output-dir",
            out,
            "--jobs",
            "1",
            tmp_path / "a" / "x.nc",
            tmp_path / "b" / "x.nc",
        ]
    )
    assert result.exit_code == 2, result.output
    assert str(tmp_path / "a" / "x.nc") in result.stderr
    assert str(tmp_path / "b" / "x.nc") in result.stderr
    assert not out.exists()  # refused before anything was written


def test_batch_output_dir_that_is_a_file_exits_3(tmp_path, program):
    blocker = tmp_path / "out"
    blocker.write_text("a file")
    result = run(["run", "--output-dir", blocker, "--jobs", "1", program])
    assert result.exit_code == 3, result.output
    assert blocker.read_text() == "a file"


# ------------------------------------------------------------------------------- signals

_SLOW_WRITER = r"""
import sys, time
import nurbscnc.output.files as files
real = files._csv_rows
def slow(fh, *args):
    real(fh, *args)
    fh.flush()
    print("WRITING", flush=True)
    time.sleep(60)
files._csv_rows = slow
from nurbscnc.cli.main import main
main(["run", sys.argv[1], "-o", sys.argv[2]])
"""


# The points made slowly (in the worker thread, cli write_output) while the writer, in the
# main thread, waits for the next window.
_SLOW_MAKER = r"""
import sys, time
import nurbscnc.pipeline as pipeline
real = pipeline.Run.chunks
def slow(self, chunk=None):
    for i, window in enumerate(real(self, 64)):
        if i == 1:
            print("WRITING", flush=True)
            time.sleep(60)
        yield window
pipeline.Run.chunks = slow
from nurbscnc.cli.main import main
main(["run", sys.argv[1], "-o", sys.argv[2]])
"""


def _interruptible() -> None:
    """In the child before it runs: Ctrl-C's default action, as at a terminal. A command
    started in the background by a non-interactive shell (a CI script's ``cmd &``) inherits
    SIGINT ignored, and Python then leaves it ignored."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


@pytest.mark.parametrize("slow", [_SLOW_WRITER, _SLOW_MAKER], ids=["writer", "maker"])
@pytest.mark.parametrize(
    "sig, code", [(signal.SIGTERM, 143), (signal.SIGHUP, 129), (signal.SIGINT, 130)]
)
def test_signal_during_run_leaves_no_temp_file(tmp_path, program, sig, code, slow):
    out = tmp_path / "out"
    out.mkdir()
    target = out / "points.csv"
    target.write_text("old\n")
    proc = subprocess.Popen(
        [sys.executable, "-c", slow, str(program), str(target)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        preexec_fn=_interruptible,
    )
    try:
        assert proc.stdout.readline().strip() == b"WRITING"
        for _ in range(200):  # the writer (the other thread) opens its temp file soon
            temps = [n for n in os.listdir(out) if n.startswith(".nurbscnc-")]
            if temps:
                break
            time.sleep(0.01)
        assert len(temps) == 1 and temps[0].endswith(".tmp")  # mid-write: the temp exists
        proc.send_signal(sig)
        rc = proc.wait(30)
        assert rc == code, proc.stderr.read().decode(errors="replace")
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert os.listdir(out) == ["points.csv"]
    assert target.read_text() == "old\n"
    assert b"Traceback" not in proc.stderr.read()


# ------------------------------------------------------------------------------- read_points


def _csv(tmp_path, rows) -> Path:
    path = tmp_path / "p.csv"
    path.write_text(",".join(POINT_COLUMNS) + "\n" + "".join(r + "\n" for r in rows))
    return path


@pytest.mark.parametrize(
    "bad, shown", [("1e308", "1e+308"), ("nan", "nan"), ("inf", "inf"), ("-1e300", "-1e+300")]
)
def test_points_csv_with_huge_or_nan_value_names_it_and_its_line(tmp_path, bad, shown):
    path = _csv(tmp_path, ["0,0,0,0,0,0,1", "", f"0.001,0,{bad},0,0,0,2"])
    with pytest.raises(DataError) as info:
        read_points(str(path))
    err = info.value
    assert f"y = {shown}" in err.message
    assert err.pos.line == 4  # header, a row, a blank line, then this one
    assert err.pos.column == len("0.001,0,") + 1


@pytest.mark.parametrize("bad, shown", [("1e308", "1e+308 is beyond"), ("nan", "nan is not")])
def test_simulate_on_points_with_huge_or_nan_value_exits_2(tmp_path, bad, shown):
    path = _csv(tmp_path, ["0,0,0,0,0,0,1", f"0.001,{bad},0,0,0,0,2", "0.002,0,0,0,0,0,2"])
    result = run(["simulate", path, "--json"])
    assert result.exit_code == 2, result.output
    first = result.stderr.splitlines()[0]
    assert first.startswith(f"{path}:3:7: error: x = {shown}")
    assert "Traceback" not in result.output


def test_points_npz_with_nan_names_the_row(tmp_path):
    path = tmp_path / "p.npz"
    cols = {c: np.zeros(5) for c in POINT_COLUMNS}
    cols["z"][3] = np.nan
    np.savez(path, **cols)
    with pytest.raises(DataError, match=r"z = nan is not finite \(row 4\)"):
        read_points(str(path))


def test_points_csv_round_trip_still_reads(tmp_path, program):
    target = tmp_path / "p.csv"
    assert run(["run", program, "-o", target]).exit_code == 0
    data = read_points(str(target))
    assert data["x"][-1] == pytest.approx(10.0, abs=1e-9)
    result = run(["simulate", target, "--json"])
    assert result.exit_code == 0, result.output
    assert json.loads(result.stdout)["samples"] == data["t"].size


@pytest.mark.parametrize(
    "body, message",
    [
        ("t,x\n", "expected the header"),
        ("t,x,y,z,feed,piece,line\n", "no reference points"),
        ("t,x,y,z,feed,piece,line\n1,2,3\n", "expected 7 columns"),
        ("t,x,y,z,feed,piece,line\n0,0,0,zz,0,0,1\n", "not a table of numbers"),
    ],
)
def test_bad_points_files_exit_2(tmp_path, body, message):
    path = tmp_path / "bad.csv"
    path.write_text(body)
    result = run(["simulate", path])
    assert result.exit_code == 2, result.output
    assert message in result.stderr


def test_points_file_that_is_a_directory_exits_3(tmp_path):
    folder = tmp_path / "pts.csv"
    folder.mkdir()
    result = run(["simulate", folder])
    assert result.exit_code == 3, result.output


def _children(pid: int) -> list[int]:
    path = Path(f"/proc/{pid}/task/{pid}/children")
    return [int(p) for p in path.read_text().split()] if path.exists() else []


def _alive(pid: int) -> bool:
    """Running (a zombie waiting for a reaper counts as gone)."""
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return False
    return "\nState:\tZ" not in status


@pytest.mark.skipif(not Path("/proc/self/task").exists(), reason="needs Linux /proc")
def test_sigterm_during_batch_stops_the_workers_and_leaves_no_temp(tmp_path):
    programs = []
    for k in range(3):
        path = tmp_path / f"p{k}.nc"
        # 300 s of motion: its 300,000 points keep a worker busy for a second or more
        path.write_text("G21 G90 G1 X300 F60\nM2\n")
        programs.append(str(path))
    out = tmp_path / "out"
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "nurbscnc",
            "run",
            "--output-dir",
            str(out),
            "--jobs",
            "2",
            "--dynamics",
            "off",
            *programs,
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    try:
        deadline = time.monotonic() + 60
        while len(_children(proc.pid)) < 2 and time.monotonic() < deadline:
            time.sleep(0.05)
        workers = _children(proc.pid)
        assert len(workers) >= 2, "the batch did not start its workers"
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(30) == 143
        at_exit = sorted(os.listdir(out))
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    deadline = time.monotonic() + 10
    while any(_alive(w) for w in workers) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not any(_alive(w) for w in workers), "workers outlived the batch"
    assert sorted(os.listdir(out)) == at_exit, "a worker wrote after the batch had ended"
    assert not [n for n in os.listdir(out) if n.startswith(".nurbscnc-")]
    # The pool may have started replacements for the terminated workers: they end too (no
    # process of the batch left, each holding the stderr pipe open).
    deadline = time.monotonic() + 10
    while _batch_processes(out) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not _batch_processes(out), "a replacement worker outlived the batch"
    _, stderr = proc.communicate(timeout=30)
    assert b"Traceback" not in stderr


def _batch_processes(out: Path) -> list[int]:
    """Live processes whose command line names the batch's output folder ``out``."""
    found = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            cmdline = (entry / "cmdline").read_bytes()
        except OSError:
            continue
        if str(out).encode() in cmdline and _alive(int(entry.name)):
            found.append(int(entry.name))
    return found


@pytest.mark.skipif(not os.path.exists("/dev/stdout"), reason="no /dev/stdout")
@pytest.mark.parametrize("name", ["/dev/stdout", "/dev/fd/1"])
def test_dev_stdout_to_a_pipe_and_to_a_file(tmp_path, program, name):
    if not os.path.exists(name):
        pytest.skip(f"no {name}")
    args = [sys.executable, "-m", "nurbscnc", "run", str(program), "-o", name, "--quiet"]
    piped = subprocess.run(args, capture_output=True, timeout=120)
    assert piped.returncode == 0, piped.stderr
    assert piped.stdout.decode().splitlines()[0] == ",".join(POINT_COLUMNS)
    target = tmp_path / "redirected.csv"
    with open(target, "wb") as fh:
        inode = os.fstat(fh.fileno()).st_ino
        redirected = subprocess.run(args, stdout=fh, stderr=subprocess.PIPE, timeout=120)
    assert redirected.returncode == 0, redirected.stderr
    assert os.stat(target).st_ino == inode  # written through the shell's file, not replaced
    assert target.read_bytes() == piped.stdout
    assert not [n for n in os.listdir(tmp_path) if n.startswith(".nurbscnc-")]


def test_a_signal_just_after_the_temp_file_is_created_leaves_no_file(tmp_path, monkeypatch):
    """A signal landing between the temporary file's creation and the code that owns it
    (here: right as ``os.open`` returns) still leaves no temporary file behind."""
    import nurbscnc.output.files as files

    real_open = os.open

    def open_then_interrupted(path, flags, mode=0o777):
        real_open(path, flags, mode)
        raise KeyboardInterrupt

    monkeypatch.setattr(files.os, "open", open_then_interrupted)
    target = tmp_path / "points.csv"
    target.write_text("old\n")
    with pytest.raises(KeyboardInterrupt), files.atomic_output(str(target)) as fh:
        fh.write("new\n")
    assert os.listdir(tmp_path) == ["points.csv"]
    assert target.read_text() == "old\n"


def test_a_signal_just_after_the_file_object_is_made_closes_the_descriptor_once(
    tmp_path, monkeypatch
):
    """A signal landing as ``os.fdopen`` returns (before the ``with`` owns the object):
    the temporary file is removed and its descriptor closed once. The object left behind
    must not close it again when it is collected: by then the number may be another
    file's (here: the next file opened gets it)."""
    import gc

    import nurbscnc.output.files as files

    real_fdopen = os.fdopen
    orphans = []

    def fdopen_then_interrupted(fd, *args, **kwargs):
        orphans.append(real_fdopen(fd, *args, **kwargs))
        raise KeyboardInterrupt

    monkeypatch.setattr(files.os, "fdopen", fdopen_then_interrupted)
    target = tmp_path / "points.csv"
    with pytest.raises(KeyboardInterrupt), files.atomic_output(str(target)) as fh:
        fh.write("new\n")
    assert os.listdir(tmp_path) == []
    closed_fd = orphans[0].fileno()
    other = os.open(tmp_path / "other", os.O_WRONLY | os.O_CREAT)
    try:
        assert other == closed_fd  # the lowest free number: the one the output had
        orphans.clear()
        gc.collect()
        os.fstat(other)  # still open: the orphan did not close it
    finally:
        os.close(other)


def test_an_interrupted_batch_ends_whatever_its_pool_does(tmp_path):
    """The safety net of a batch stopped by a signal (cli.batch._stop_batch): the workers are
    told at once, and the parent exits as for the signal within BATCH_STOP_S even if what
    follows blocks for ever (here a sleep stands for the pool's shutdown waiting on a lock
    a dying worker held; a CI run saw such a parent still alive 30 s after SIGTERM)."""
    code = (
        "import multiprocessing, time\n"
        "from nurbscnc.cli.batch import _stop_batch\n"
        "from nurbscnc.cli.handle import Terminated as _Terminated\n"
        "worker = multiprocessing.Process(target=time.sleep, args=(120,))\n"
        "worker.start()\n"
        "print(worker.pid, flush=True)\n"
        "_stop_batch(_Terminated(15))\n"
        "time.sleep(120)\n"
    )
    start = time.monotonic()
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    from nurbscnc.cli.batch import BATCH_STOP_S

    assert proc.returncode == 143, proc.stderr
    assert time.monotonic() - start < BATCH_STOP_S + 20
    worker = int(proc.stdout.split()[0])
    with pytest.raises(ProcessLookupError):  # the worker was ended, not left behind
        for _ in range(100):
            os.kill(worker, 0)
            time.sleep(0.05)
