"""The package as a user installs it: a wheel built from the repository, installed (not editable)
into a fresh virtual environment, run from a folder that is not the repository; then, in the same
environment, the README's ``pip install -e .``. Everything runs on a PATH with no C compiler (the
venv's bin folder and an empty one; ``CC`` and ``CXX`` are ``/bin/false``), as on a machine with
Python alone: a dependency that only builds from source fails the install.

The shipped textures and device files must come with it as package data. Building and
installing needs the build backend and the dependencies from a package index (or pip's
cache): without one the test skips, and fails under TPAD_RT_REQUIRE_SYSTEM=1. pip runs here with a cache of its
own (:data:`PIP_CACHE`), which only installs on a PATH without a compiler write to: a wheel pip built from
source and cached there was built without one (the user's cache may hold one built with a compiler: tests/run's
``pip install -e .`` builds cobs with one), and the next run reuses it instead of building everything again.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import venv
from collections.abc import Iterator
from pathlib import Path

import pytest
from conftest import REPO_ROOT, require_system

from tpad_rt.compiling import NOTICE

pytestmark = [pytest.mark.slow, pytest.mark.system]
#: What builds C extensions: none of them may be on the PATH the installs run on.
COMPILERS = ("cc", "gcc", "clang", "c++", "g++", "clang++", "x86_64-linux-gnu-gcc")
#: pip's cache for the installs here: downloads, and the wheels pip built without a compiler (module docstring).
PIP_CACHE = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "tpad-rt-tests" / "pip-no-compiler"


def _run(command: list[str], cwd: Path, env: dict[str, str], timeout_s: float = 600) -> subprocess.CompletedProcess[str]:
    return subprocess.run(command, cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout_s, check=False)


def _without_compilers(env: dict[str, str], bin_dir: Path, empty: Path) -> dict[str, str]:
    """``env`` on a PATH of ``bin_dir`` (the venv's) and ``empty``, with ``CC`` and ``CXX`` failing: no compiler
    of COMPILERS can be found (asserted)."""
    path = os.pathsep.join([str(bin_dir), str(empty)])
    assert [name for name in COMPILERS if shutil.which(name, path=path)] == []
    return {**env, "PATH": path, "CC": "/bin/false", "CXX": "/bin/false"}


@pytest.fixture(scope="module")
def installed(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[Path, dict[str, str]]]:
    """``(bin folder of a fresh venv holding the wheel, environment to run it in)``."""
    root = tmp_path_factory.mktemp("wheel")
    env = {key: value for key, value in os.environ.items()
           if key not in ("PYTHONPATH", "VIRTUAL_ENV", "DISPLAY", "PYTHONHOME")}
    env.update(PIP_DISABLE_PIP_VERSION_CHECK="1", PIP_CACHE_DIR=str(PIP_CACHE))
    bin_dir = root / "venv" / "bin"
    (root / "empty").mkdir()
    env = _without_compilers(env, bin_dir, root / "empty")
    built = _run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(root / "dist"), str(REPO_ROOT)],
                 root, env)
    require_system(built.returncode == 0, f"a wheel build (pip wheel: {built.stderr.strip()[-300:]})")
    wheels = sorted((root / "dist").glob("tpad_rt-*.whl"))
    assert len(wheels) == 1, wheels
    venv.create(root / "venv", with_pip=True)
    # --no-compile: byte-compiling every dependency's modules took half of the install (24 of 42 s); Python
    # compiles what it imports when it imports it. --only-binary=:all:: wheels only, as on a machine with no C
    # compiler (python-evdev, which pynput pulls in on Linux, is source only: it is the extra tpad-rt[inputs]).
    done = _run([str(bin_dir / "python"), "-m", "pip", "install", "-q", "--no-compile", "--only-binary=:all:",
                 str(wheels[0])], root, env)
    require_system(done.returncode == 0, f"the wheel's dependencies (pip install: {done.stderr.strip()[-300:]})")
    env["NUMBA_CACHE_DIR"] = str(root / "numba-cache")
    elsewhere = root / "elsewhere"
    elsewhere.mkdir()
    yield bin_dir, env


def test_the_wheel_holds_the_package_not_the_repository(installed: tuple[Path, dict[str, str]]) -> None:
    bin_dir, env = installed
    where = _run([str(bin_dir / "python"), "-c",
                  "import tpad_rt, tpad_rt.shipped as s; from tpad_rt.device import Device; "
                  "print(tpad_rt.__file__); print(s.DEFAULT_DEVICE); print(Device.default().label); "
                  "print(len(s.texture_names()), len(s.device_names()))"],
                 bin_dir.parent.parent / "elsewhere", env)
    assert where.returncode == 0, where.stderr
    module, default, label, counts = where.stdout.split("\n")[:4]
    venv_dir = bin_dir.parent
    assert Path(module).is_relative_to(venv_dir) and Path(default).is_relative_to(venv_dir)
    assert not Path(module).is_relative_to(REPO_ROOT)
    assert label == "SLG_0.56"
    shipped_textures = len(list((REPO_ROOT / "tpad_rt" / "textures").glob("*.yaml")))
    shipped_devices = len(list((REPO_ROOT / "tpad_rt" / "devices").glob("*.yaml")))
    assert counts == f"{shipped_textures} {shipped_devices}"


def test_tpad_rt_play_runs_a_shipped_texture_from_any_folder(installed: tuple[Path, dict[str, str]]) -> None:
    """The installed package's first run (the first test here to run the kernels, in the venv's empty numba cache):
    its first line is the compile notice (stderr), the whole compile plan compiles before the clock starts (the plan's
    mark is in the cache after it), and the next run is silent."""
    bin_dir, env = installed
    elsewhere = bin_dir.parent.parent / "elsewhere"
    play = [str(bin_dir / "tpad-rt"), "play", "grating", "--output", "sim://", "--duration"]
    played = _run([*play, "1"], elsewhere, env)
    assert played.returncode == 0, played.stderr
    assert "played " in played.stdout and "drive: peak" in played.stdout, played.stdout
    notice = played.stderr.splitlines()
    assert notice[0].startswith(NOTICE)  # the whole plan, in workers: progress lines, then what it compiled
    assert all(line.startswith("tpad-rt: compiling: ") for line in notice[1:-1]), notice
    assert notice[-1].startswith("tpad-rt: compiled ") and " cached in " in notice[-1]
    assert int(notice[-1].split()[2]) > 10  # functions compiled: the kernels, not a stray one
    complete = _run([str(bin_dir / "python"), "-c", "from tpad_rt.kernel_cache import plan_complete; "
                     "print(plan_complete())"], elsewhere, env)
    assert complete.stdout.split() == ["True"], complete.stderr
    warm = _run([*play, "0.2"], elsewhere, env)
    assert warm.returncode == 0 and warm.stderr == ""
    # a texture with an image asset: the assets are package data too
    path = _run([str(bin_dir / "python"), "-c",
                 "from tpad_rt.texture import load_compiled; print(load_compiled('bitmap_logo').img.size)"],
                elsewhere, env)
    assert path.returncode == 0 and int(path.stdout) > 0, path.stderr


def test_a_repository_path_outside_the_repository_names_the_shipped_texture(
        installed: tuple[Path, dict[str, str]]) -> None:
    bin_dir, env = installed
    done = _run([str(bin_dir / "tpad-rt"), "play", "textures/grating.yaml", "--duration", "0.5"],
                bin_dir.parent.parent / "elsewhere", env)
    assert done.returncode != 0
    assert done.stderr.strip() == ("tpad-rt play: textures/grating.yaml: no such file; the package ships a texture "
                                   "of that name: give just 'grating'")


def test_serve_finds_its_page_in_the_installed_package(installed: tuple[Path, dict[str, str]]) -> None:
    """The page's files are package data: the installed package holds them, and ``serve`` starts with them."""
    bin_dir, env = installed
    elsewhere = bin_dir.parent.parent / "elsewhere"
    files = _run([str(bin_dir / "python"), "-c",
                  "from importlib import resources; from tpad_rt.serve.server import STATIC_FILES; "
                  "print(*sorted({len(resources.files('tpad_rt.serve').joinpath('static', name).read_bytes()) > 0 "
                  "for name, _ in STATIC_FILES.values()}))"], elsewhere, env)
    assert files.returncode == 0 and files.stdout.split() == ["True"], files.stderr
    served = _run([str(bin_dir / "tpad-rt"), "serve", "grating", "--output", "null://", "--port", "0", "--no-osc",
                   "--duration", "0.5"], elsewhere, env)
    assert served.returncode == 0, served.stderr
    assert "serving http://127.0.0.1:" in served.stdout and "served until --duration" in served.stdout


def test_without_the_inputs_extra_the_mouse_says_what_to_install(installed: tuple[Path, dict[str, str]]) -> None:
    """The wheel installed from wheels alone (the fixture) holds neither pynput nor python-evdev: the mouse asks
    for the extra in one line, and play's auto input takes the scripted swipe and says why."""
    bin_dir, env = installed
    elsewhere = bin_dir.parent.parent / "elsewhere"
    absent = _run([str(bin_dir / "python"), "-c",
                   "import importlib.util as u; print(u.find_spec('pynput'), u.find_spec('evdev'))"], elsewhere, env)
    assert absent.stdout.split() == ["None", "None"], absent.stderr
    play = [str(bin_dir / "tpad-rt"), "play", "grating", "--output", "sim://", "--duration", "0.2"]
    mouse = _run([*play, "--input", "mouse://"], elsewhere, env)
    assert mouse.returncode == 1 and "Traceback" not in mouse.stderr
    assert mouse.stderr.strip().splitlines()[-1] == (
        "tpad-rt play: input mouse://: needs pynput, which is not installed: pip install 'tpad-rt[inputs]' (on Linux "
        "it needs a C compiler and the kernel headers, for python-evdev); or use --input scripted://swipe")
    auto = _run(play, elsewhere, {**env, "DISPLAY": ":0"})
    assert auto.returncode == 0, auto.stderr
    assert "(no pynput for the mouse: pip install 'tpad-rt[inputs]'" in auto.stdout.splitlines()[0], auto.stdout



def test_the_readme_editable_install_needs_no_compiler_either(installed: tuple[Path, dict[str, str]]) -> None:
    """``pip install -e .`` (the README's set-up) in the same environment on the PATH without a compiler, every
    dependency upgraded to what pip picks for a fresh environment (no ``--only-binary``: a newest release that is
    source only, cobs 1.2.2 today, is built here, or taken from :data:`PIP_CACHE` where an earlier run built it
    without a compiler): it installs, ``tpad_rt`` then comes from the repository, and no distribution in the
    environment is a platform wheel built on some machine (a ``linux_*`` tag, not ``manylinux``: what pip
    installs from a wheel it built with a compiler, or took from a cache holding one). It replaces the wheel in
    the venv: the last test of this file."""
    bin_dir, env = installed
    elsewhere = bin_dir.parent.parent / "elsewhere"
    done = _run([str(bin_dir / "python"), "-m", "pip", "install", "-q", "--no-compile", "--upgrade",
                 "--upgrade-strategy", "eager", "-e", str(REPO_ROOT)], elsewhere, env)
    assert done.returncode == 0, done.stderr[-3000:]
    where = _run([str(bin_dir / "python"), "-c", "import tpad_rt; print(tpad_rt.__file__)"], elsewhere, env)
    assert where.returncode == 0 and Path(where.stdout.strip()).is_relative_to(REPO_ROOT), where.stderr
    built_somewhere = [wheel.parent.name for wheel in bin_dir.parent.glob("lib/python*/site-packages/*.dist-info/WHEEL")
                       if any(line.startswith("Tag:") and "-linux_" in line for line in wheel.read_text().splitlines())]
    assert built_somewhere == []
