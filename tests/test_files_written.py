"""Files written at paths the user names (tpad_rt.files.NewFile), attacked in a real folder.

Written as an attacker who can create files in the folder the user writes to (a shared
``/tmp``) would try: links planted at the temporary names a writer could pick (the old
predictable ``.NAME.PID.tmp``, and the random names, guessed right) and at the target
itself, the target swapped for a FIFO, a directory, a device or a link while the file
is being written, a folder that cannot be written (by a user: read-only or not
searchable; by root: immutable), and failures and crashes mid-write. What must hold: a victim file elsewhere is never
written, the file at the target is the old one or the whole new one and never part of
one, no temporary file stays behind when the writer fails (only a process killed
outright can leave one, hidden beside the target), nothing hangs, and every mistake is
one ConfigError or BackendError line, never a traceback.

The command-line cases run the real CLI (tests/cli_run.py) on ``calibrate build``,
``calibrate convert``, ``render --out``, ``--output wav://``, ``show --out`` and
``schema --out``.
"""

from __future__ import annotations

import contextlib
import errno
import os
import resource
import shutil
import signal
import socket
import stat
import subprocess
import sys
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pytest

from cli_run import REPO, tpad_rt, warm_numba_cache
from tpad_rt.calibrate.device_file import convert_document, write_device
from tpad_rt.device import Device
from tpad_rt.errors import BackendError, ConfigError
from tpad_rt.files import NewFile
from tpad_rt.outputs import open_output

EXAMPLE = REPO / "examples" / "calibration"
FORMAT_1 = REPO / "tests" / "bad_files" / "device_format_1.yaml"
GRATING = str(REPO / "textures" / "grating.yaml")
STILL = "scripted://still?duration_s=0.01"
PRECIOUS = b"the victim's own bytes\n"


@pytest.fixture
def victim(tmp_path: Path) -> Path:
    """A file outside the folder written to, which no write may change."""
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    path = elsewhere / "victim.txt"
    path.write_bytes(PRECIOUS)
    return path


@pytest.fixture
def folder(tmp_path: Path) -> Path:
    """The folder the user writes to (and the attacker can write in)."""
    path = tmp_path / "shared"
    path.mkdir()
    return path


def _leftovers(folder: Path) -> list[str]:
    """Temporary files left in ``folder`` (NewFile's ``.NAME.XXXXXXXX.tmp``, the old ``.NAME.PID.tmp``)."""
    return sorted(path.name for path in folder.iterdir() if path.name.startswith(".") and path.name.endswith(".tmp")
                  and not path.is_symlink())


@contextlib.contextmanager
def _no_hang(seconds: int = 20) -> Iterator[None]:
    """Fail (instead of hanging the suite) when the block takes longer than ``seconds``: a FIFO opened without
    O_NONBLOCK blocks until a reader comes."""
    def expire(signum: int, frame: object) -> None:
        raise AssertionError(f"hung for {seconds} s")

    previous = signal.signal(signal.SIGALRM, expire)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)


@contextlib.contextmanager
def _immutable(path: Path) -> Iterator[None]:
    """``path`` made immutable (``chattr +i``): nothing, root included, may create, remove or rename in it
    (a folder) or replace it (a file). Skips where the file system or the capabilities do not allow it."""
    if shutil.which("chattr") is None:
        pytest.skip("chattr (e2fsprogs) is not installed: no way to make a folder root cannot write")
    done = subprocess.run(["chattr", "+i", str(path)], capture_output=True, text=True, check=False)
    if done.returncode != 0:
        pytest.skip(f"chattr +i is not allowed here ({done.stderr.strip()}): no folder root cannot write")
    try:
        yield
    finally:
        subprocess.run(["chattr", "-i", str(path)], check=True)


def _write(path: Path, data: bytes, what: str = "things") -> None:
    with NewFile(path, what) as new:
        new.file.write(data)


# --- links planted at the temporary names ---------------------------------------------------------------------

def test_a_link_at_the_old_predictable_temporary_name_is_not_followed(folder: Path, victim: Path) -> None:
    """calibrate build and convert wrote '.NAME.PID.tmp' with write_text, following a link planted there: the
    victim was overwritten and the link then renamed onto the target."""
    planted = folder / f".rig.yaml.{os.getpid()}.tmp"
    planted.symlink_to(victim)
    document, _ = convert_document(FORMAT_1)
    device = write_device(document, folder / "rig.yaml")
    assert victim.read_bytes() == PRECIOUS
    assert planted.is_symlink() and os.readlink(planted) == str(victim)
    target = folder / "rig.yaml"
    assert not target.is_symlink() and Device.from_file(target).label == device.label
    assert _leftovers(folder) == []


def test_a_device_that_does_not_load_is_not_written_and_its_errors_name_the_target(tmp_path: Path) -> None:
    """write_device loads the temporary file before renaming it: its errors name the target (escaped as every
    message does), never the temporary file, and nothing is left."""
    folder = tmp_path / "odd\nfolder"
    folder.mkdir()
    document, _ = convert_document(FORMAT_1)
    document["max_voltage_v"] = -1
    with pytest.raises(ConfigError) as caught:
        write_device(document, folder / "rig.yaml")
    assert str(caught.value).startswith(f"{tmp_path}/odd\\x0afolder/rig.yaml (not written): max_voltage_v: ")
    assert ".tmp" not in str(caught.value) and os.listdir(folder) == []


def test_links_at_the_random_temporary_names_are_refused_even_when_guessed(
        folder: Path, victim: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """An attacker who guesses the random names (here: is told them) still cannot make the writer follow a link:
    the temporary file is created with O_EXCL | O_NOFOLLOW, so a name that exists is skipped, never opened."""
    names = ["guessed1", "guessed2", "guessed3", "notplant"]
    for name in names[:3]:
        (folder / f".out.bin.{name}.tmp").symlink_to(victim)
    (folder / ".out.bin.guessed3.tmp").unlink()
    (folder / ".out.bin.guessed3.tmp").symlink_to(folder / "nowhere")  # a dangling link: O_CREAT would make it
    monkeypatch.setattr(tempfile, "_get_candidate_names", lambda: iter(names))
    with NewFile(folder / "out.bin", "things") as new:
        assert Path(new.temporary).name == ".out.bin.notplant.tmp"
        new.file.write(b"new")
    assert victim.read_bytes() == PRECIOUS and not (folder / "nowhere").exists()
    assert (folder / "out.bin").read_bytes() == b"new"
    assert all((folder / f".out.bin.{name}.tmp").is_symlink() for name in names[:3])
    assert _leftovers(folder) == []


def test_a_long_name_still_leaves_room_for_the_temporary_name(folder: Path) -> None:
    target = folder / ("n" * 250 + ".npz")  # 254 bytes: NAME_MAX is 255
    _write(target, b"long")
    assert target.read_bytes() == b"long" and _leftovers(folder) == []


# --- what is at the target ---------------------------------------------------------------------------------------

def test_a_link_at_the_target_is_replaced_and_its_file_never_written(folder: Path, victim: Path) -> None:
    target = folder / "out.yaml"
    target.symlink_to(victim)
    _write(target, b"mine")
    assert victim.read_bytes() == PRECIOUS
    assert not target.is_symlink() and target.read_bytes() == b"mine"


def test_a_hard_link_at_the_target_is_replaced_and_its_other_name_never_written(folder: Path, victim: Path) -> None:
    """A plain open(path, "w") writes through a hard link to the victim (where the file system lets the attacker
    make one); the rename replaces the folder's entry instead."""
    target = folder / "out.yaml"
    os.link(victim, target)
    _write(target, b"mine")
    assert victim.read_bytes() == PRECIOUS and target.read_bytes() == b"mine"
    assert os.stat(victim).st_nlink == 1


def test_a_dangling_link_at_the_target_creates_nothing_where_it_points(folder: Path, victim: Path) -> None:
    target, aimed = folder / "out.yaml", victim.parent / "planted-by-the-writer"
    target.symlink_to(aimed)
    _write(target, b"mine")
    assert not aimed.exists() and not target.is_symlink() and target.read_bytes() == b"mine"


def _special(folder: Path, kind: str) -> Path:
    """A non-regular file of ``kind`` at ``folder/target``, or a link to one."""
    target = folder / "target"
    if kind == "FIFO":
        os.mkfifo(target)
    elif kind == "directory":
        target.mkdir()
        (target / "inside").write_bytes(PRECIOUS)
    elif kind == "socket":
        sock = socket.socket(socket.AF_UNIX)
        sock.bind(str(target))
        sock.close()
    elif kind == "character device":
        target.symlink_to("/dev/null")
    elif kind == "link to a FIFO":
        os.mkfifo(folder / "fifo")
        target.symlink_to(folder / "fifo")
    return target


@pytest.mark.parametrize(("kind", "shown"), [("FIFO", "a FIFO"), ("directory", "a directory"), ("socket", "a socket"),
                                             ("character device", "a character device"),
                                             ("link to a FIFO", "a FIFO")])
def test_a_target_that_is_not_a_regular_file_is_refused_at_once_without_hanging(folder: Path, kind: str,
                                                                                 shown: str) -> None:
    target = _special(folder, kind)
    before = sorted(os.listdir(folder))
    with _no_hang(), pytest.raises(ConfigError) as caught:
        _write(target, b"x")
    assert str(caught.value) == (f"{target}: exists and is not a regular file ({shown}); tpad-rt writes things to "
                                 "regular files only")
    assert sorted(os.listdir(folder)) == before
    if kind == "directory":
        assert (target / "inside").read_bytes() == PRECIOUS


def test_a_target_swapped_while_written_is_replaced_never_written_through(folder: Path, victim: Path) -> None:
    """Swapped for a link after the check: the link is replaced. Swapped for a FIFO: replaced, no hang."""
    for swap in ("link", "fifo"):
        target = folder / f"{swap}.bin"
        with _no_hang(), NewFile(target, "things") as new:
            new.file.write(b"whole")
            if swap == "link":
                target.symlink_to(victim)
            else:
                os.mkfifo(target)
        assert target.read_bytes() == b"whole" and victim.read_bytes() == PRECIOUS
    assert _leftovers(folder) == []


def test_a_target_swapped_for_a_directory_while_written_fails_in_one_line(folder: Path) -> None:
    target = folder / "out.bin"
    with pytest.raises(BackendError) as caught, NewFile(target, "things") as new:
        new.file.write(b"whole")
        target.mkdir()
        (target / "inside").write_bytes(PRECIOUS)
    assert str(caught.value).startswith(f"{target}: cannot write things there: ")
    assert "\n" not in str(caught.value)
    assert (target / "inside").read_bytes() == PRECIOUS and _leftovers(folder) == []


@pytest.mark.parametrize(("path", "expected"), [
    ("missing/out.bin", "out.bin: cannot write things there: no folder "),
    ("afile/out.bin", "out.bin: cannot write things there: no folder "),
    ("n" * 300 + ".bin", ".bin: cannot write things there: file name too long"),
    ("a\0b.bin", "the path contains a NUL byte"),
])
def test_no_place_to_write_is_one_config_error(folder: Path, path: str, expected: str) -> None:
    (folder / "afile").write_bytes(PRECIOUS)
    with pytest.raises(ConfigError, match=expected.replace(".", r"\.")):
        _write(folder / path, b"x")
    assert sorted(os.listdir(folder)) == ["afile"]


def test_a_folder_not_even_root_can_write_is_refused_before_anything_is_written(folder: Path) -> None:
    (folder / "old.yaml").write_bytes(PRECIOUS)
    with _immutable(folder), pytest.raises(ConfigError) as caught:
        _write(folder / "old.yaml", b"x")
    assert str(caught.value) == f"{folder}/old.yaml: cannot write things there: the folder {folder} is not writable"
    assert (folder / "old.yaml").read_bytes() == PRECIOUS and _leftovers(folder) == []


@contextlib.contextmanager
def _as_a_user() -> Iterator[None]:
    """The block runs as a user other than root: as root, with the effective user id set to nobody's (65534)
    (the real one stays root, so os.access still says yes and a folder's refusal comes from creating the
    temporary file in it)."""
    if os.geteuid() != 0:
        yield
        return
    os.seteuid(65534)
    try:
        yield
    finally:
        os.seteuid(0)


def test_a_read_only_folder_is_refused_for_a_user_and_the_old_file_kept() -> None:
    top = Path(tempfile.mkdtemp(prefix="tpad-rt-read-only-"))  # under /tmp: pytest's own folders are root's alone
    try:
        top.chmod(0o755)
        folder, hidden = top / "read-only", top / "unsearchable"
        for path, mode in ((folder, 0o555), (hidden, 0o700 if os.geteuid() == 0 else 0o000)):
            path.mkdir()
            (path / "old.yaml").write_bytes(PRECIOUS)
            path.chmod(mode)
        with _as_a_user():
            with pytest.raises(ConfigError) as caught:
                _write(folder / "old.yaml", b"x")
            assert str(caught.value) in (
                f"{folder}/old.yaml: cannot write things there: the folder {folder} is not writable",  # os.access
                f"{folder}/old.yaml: cannot write things there: the folder {folder} is not writable (permission "
                "denied)")
            with pytest.raises(ConfigError) as caught:
                _write(hidden / "old.yaml", b"x")
            assert str(caught.value) == f"{hidden}/old.yaml: cannot write things there: permission denied"
        for path in (folder, hidden):
            path.chmod(0o755)
            assert (path / "old.yaml").read_bytes() == PRECIOUS and os.listdir(path) == ["old.yaml"]
    finally:
        for path in top.iterdir():
            path.chmod(0o755)
        shutil.rmtree(top)


def test_a_target_that_cannot_be_replaced_fails_at_commit_leaving_it_whole(folder: Path) -> None:
    """An immutable target (root cannot replace it either): the rename fails; the old file and the folder are as
    they were."""
    target = folder / "old.npz"
    target.write_bytes(PRECIOUS)
    with _immutable(target), pytest.raises(BackendError) as caught:
        _write(target, b"x" * 100_000)
    assert str(caught.value) == f"{target}: cannot write things there: operation not permitted"
    assert target.read_bytes() == PRECIOUS and _leftovers(folder) == []


# --- failures and crashes mid-write ------------------------------------------------------------------------------

def test_an_error_mid_write_leaves_the_old_file_and_no_temporary_file(folder: Path) -> None:
    target = folder / "old.yaml"
    target.write_bytes(PRECIOUS)
    with pytest.raises(KeyError), NewFile(target, "things") as new:
        new.file.write(b"half")
        raise KeyError("the writer's own bug")
    with pytest.raises(BackendError, match=r"old\.yaml: cannot write things there: no space left on device$"):
        with NewFile(target, "things") as new:
            new.file.write(b"half")
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
    assert target.read_bytes() == PRECIOUS and sorted(os.listdir(folder)) == ["old.yaml"]


def test_a_discarded_temporary_name_taken_by_another_is_left_to_it(folder: Path) -> None:
    """Once discarded, the temporary name is free: a file someone makes there is not removed by a second discard
    (the wav output discards on a write error and again as its block ends)."""
    new = NewFile(folder / "out.bin", "things")
    new.discard()
    Path(new.temporary).write_bytes(PRECIOUS)
    new.discard()
    new.commit()
    assert Path(new.temporary).read_bytes() == PRECIOUS and not (folder / "out.bin").exists()


def test_nothing_is_at_the_target_until_the_file_is_whole(folder: Path) -> None:
    target = folder / "old.yaml"
    target.write_bytes(PRECIOUS)
    with NewFile(target, "things") as new:
        new.file.write(b"1" * 1_000_000)
        new.file.flush()
        assert target.read_bytes() == PRECIOUS
    assert target.read_bytes() == b"1" * 1_000_000


_KILLED_MID_WRITE = """
import os, sys
from tpad_rt.files import NewFile
new = NewFile(sys.argv[1], "things")
new.file.write(b"half of the new file")
new.file.flush()
os.kill(os.getpid(), 9)
"""


def test_a_writer_killed_mid_write_leaves_the_old_file_whole(folder: Path) -> None:
    """SIGKILL cannot be cleaned up after: the temporary file stays, hidden beside the target, which is intact."""
    target = folder / "old.yaml"
    target.write_bytes(PRECIOUS)
    done = subprocess.run([sys.executable, "-c", _KILLED_MID_WRITE, str(target)], check=False)
    assert done.returncode == -signal.SIGKILL
    assert target.read_bytes() == PRECIOUS
    left = _leftovers(folder)
    assert len(left) == 1 and left[0].startswith(".old.yaml.")
    assert stat.S_IMODE(os.stat(folder / left[0]).st_mode) == 0o600  # no one else could read it meanwhile


def test_the_file_gets_the_mode_a_plain_open_would(folder: Path) -> None:
    previous = os.umask(0o027)
    try:
        _write(folder / "new.bin", b"x")
        assert stat.S_IMODE(os.stat(folder / "new.bin").st_mode) == 0o640
        os.chmod(folder / "new.bin", 0o604)
        _write(folder / "new.bin", b"y")  # replacing a file keeps its permissions
        assert stat.S_IMODE(os.stat(folder / "new.bin").st_mode) == 0o604
    finally:
        os.umask(previous)


def test_a_wav_output_appears_only_when_closed_and_not_at_all_after_an_error(folder: Path) -> None:
    target = folder / "out.wav"
    target.write_bytes(PRECIOUS)
    with pytest.raises(RuntimeError), open_output(f"wav://{target}", device=Device.default(), fs_hz=48000) as output:
        output.write(np.zeros(480, dtype=np.float32), {})
        assert target.read_bytes() == PRECIOUS
        raise RuntimeError("the run failed")
    assert target.read_bytes() == PRECIOUS and sorted(os.listdir(folder)) == ["out.wav"]
    with open_output(f"wav://{target}", device=Device.default(), fs_hz=48000) as output:
        output.write(np.zeros(480, dtype=np.float32), {})
    assert target.stat().st_size == 58 + 4 * 480 and sorted(os.listdir(folder)) == ["out.wav"]


# --- the command line ---------------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def _warm() -> None:
    """Compile the kernels into numba's cache first (cli_run.warm_numba_cache)."""
    warm_numba_cache()


def _next_pids(count: int) -> list[int]:
    """The ``count`` process ids the next processes will most likely get (ids are handed out in turn)."""
    pid_max = int(Path("/proc/sys/kernel/pid_max").read_text())
    with subprocess.Popen(["true"]) as child:
        start = child.pid
    return [(start + step) % pid_max for step in range(1, count + 1)]


#: A calibrate command line writing to the path given.
Command = Callable[[Path], tuple[str, ...]]


def _build(out: Path) -> tuple[str, ...]:
    return ("calibrate", "build", "--impedance", str(EXAMPLE / "sweeps.csv"), "--amplitude",
            str(EXAMPLE / "amplitudes.csv"), "--out", str(out))


def _convert(out: Path) -> tuple[str, ...]:
    return ("calibrate", "convert", str(FORMAT_1), "--out", str(out))


@pytest.mark.parametrize("command", [_build, _convert])
def test_calibrate_follows_no_link_planted_at_the_temporary_names(folder: Path, victim: Path,
                                                                  command: Command) -> None:
    """The old temporary name held the writer's PID: the attacker plants a link for each PID it may get."""
    out = folder / "rig.yaml"
    for pid in _next_pids(3000):
        (folder / f".rig.yaml.{pid}.tmp").symlink_to(victim)
    run = tpad_rt(*command(out))
    assert run.returncode == 0, run.stderr
    assert victim.read_bytes() == PRECIOUS
    assert not out.is_symlink() and Device.from_file(out).label
    assert _leftovers(folder) == []


@pytest.mark.parametrize("command", [_build, _convert])
def test_calibrate_replaces_a_link_at_its_out_and_leaves_the_victim(folder: Path, victim: Path,
                                                                    command: Command) -> None:
    out = folder / "rig.yaml"
    out.symlink_to(victim)
    run = tpad_rt(*command(out))
    assert run.returncode == 0, run.stderr
    assert victim.read_bytes() == PRECIOUS and not out.is_symlink() and Device.from_file(out).label


def test_calibrate_refuses_an_out_that_links_to_its_own_input(folder: Path) -> None:
    old = folder / "old.yaml"
    old.write_bytes(FORMAT_1.read_bytes())
    (folder / "new.yaml").symlink_to(old)
    tpad_rt(*_convert(folder / "new.yaml")[:2], str(old), "--out", str(folder / "new.yaml")).assert_one_line_error(
        f"{folder / 'new.yaml'}: is also a file this command reads ({old}): write to another file")
    assert old.read_bytes() == FORMAT_1.read_bytes() and (folder / "new.yaml").is_symlink()


@pytest.mark.parametrize("command", [_build, _convert])
@pytest.mark.parametrize("kind", ["FIFO", "directory", "socket", "character device", "link to a FIFO"])
def test_calibrate_refuses_an_out_that_is_not_a_regular_file_in_one_line(folder: Path, command: Command,
                                                                         kind: str) -> None:
    target = _special(folder, kind)
    tpad_rt(*command(target), timeout_s=60).assert_one_line_error(
        f"{target}: exists and is not a regular file")
    assert _leftovers(folder) == []


@pytest.mark.parametrize("command", [_build, _convert])
def test_calibrate_in_a_folder_root_cannot_write_is_one_line_and_the_old_file_kept(folder: Path,
                                                                                  command: Command) -> None:
    out = folder / "rig.yaml"
    out.write_bytes(PRECIOUS)
    with _immutable(folder):
        tpad_rt(*command(out)).assert_one_line_error(
            f"{out}: cannot write device files there: the folder {folder} is not writable")
    assert out.read_bytes() == PRECIOUS and _leftovers(folder) == []


@pytest.mark.usefixtures("_warm")
@pytest.mark.parametrize("suffix", [".npz", ".wav"])
def test_render_replaces_a_link_at_its_out_and_leaves_the_victim(folder: Path, victim: Path, suffix: str) -> None:
    out = folder / f"drive{suffix}"
    out.symlink_to(victim)
    run = tpad_rt("render", GRATING, "--input", STILL, "--out", str(out))
    assert run.returncode == 0, run.stderr
    assert victim.read_bytes() == PRECIOUS and not out.is_symlink() and out.stat().st_size > 58


@pytest.mark.usefixtures("_warm")
def test_a_wav_output_url_replaces_a_link_and_leaves_the_victim(folder: Path, victim: Path) -> None:
    wav = folder / "drive.wav"
    wav.symlink_to(victim)
    run = tpad_rt("render", GRATING, "--input", STILL, "--output", f"wav://{wav}", "--out", str(folder / "r.npz"))
    assert run.returncode == 0, run.stderr
    assert victim.read_bytes() == PRECIOUS and not wav.is_symlink() and wav.stat().st_size > 58
    assert sorted(os.listdir(folder)) == ["drive.wav", "r.npz"]


def test_show_and_schema_replace_a_link_at_their_out_and_leave_the_victim(folder: Path, victim: Path) -> None:
    for args, out in ((("show", GRATING, "--resolution-mm", "2", "--out"), folder / "map.png"),
                      (("schema", "device", "--out"), folder / "device.json")):
        out.symlink_to(victim)
        run = tpad_rt(*args, str(out))
        assert run.returncode == 0, run.stderr
        assert victim.read_bytes() == PRECIOUS and not out.is_symlink() and out.stat().st_size > 1000
    assert _leftovers(folder) == []


def _limit_file_size() -> None:
    """In the child: files may grow to 64 KiB, and passing that fails the write (EFBIG) instead of killing it."""
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    resource.setrlimit(resource.RLIMIT_FSIZE, (65536, 65536))


@pytest.mark.usefixtures("_warm")
@pytest.mark.parametrize("suffix", [".npz", ".wav"])
def test_a_render_whose_file_cannot_be_written_whole_is_one_line_and_the_old_file_kept(folder: Path,
                                                                                      suffix: str) -> None:
    """A file-size limit (as a full disk would) stops the write part way: the old file stays, whole."""
    out = folder / f"old{suffix}"
    out.write_bytes(PRECIOUS)
    done = subprocess.run([sys.executable, "-m", "tpad_rt", "render", GRATING, "--input",
                           "scripted://still?duration_s=0.5", "--out", str(out)], cwd=REPO, capture_output=True,
                          text=True, timeout=300, preexec_fn=_limit_file_size, check=False)
    assert done.returncode == 1, done.stderr
    assert done.stderr == f"tpad-rt render: {out}: cannot write {'recordings' if suffix == '.npz' else 'WAV files'} " \
                          "there: file too large\n"
    assert out.read_bytes() == PRECIOUS and sorted(os.listdir(folder)) == [out.name]
