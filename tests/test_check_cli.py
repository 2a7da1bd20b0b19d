"""``tpad-rt check`` and ``tpad-rt schema`` from the command line."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from test_config_bad_files import expected_lines
from tpad_rt.cli import main
from tpad_rt.config import schema_json

TESTS = Path(__file__).parent
GOOD = TESTS / "good_files"
BAD = TESTS / "bad_files"


def _run(*args: str, **env: str) -> subprocess.CompletedProcess[str]:
    environment = {key: value for key, value in os.environ.items() if key not in ("FORCE_COLOR", "NO_COLOR")}
    return subprocess.run(
        [sys.executable, "-m", "tpad_rt", *args],
        capture_output=True,
        text=True,
        cwd=TESTS.parent,
        env={**environment, **env},
        timeout=120,
    )


def test_good_files_print_ok(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["check", str(GOOD / "grating.yaml")]) == 0
    out, err = capsys.readouterr()
    assert out == f"ok  {GOOD / 'grating.yaml'} (texture: grating)\n"
    assert err == ""


def test_device_file_prints_its_label(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["check", str(GOOD / "device.yaml")]) == 0
    assert capsys.readouterr().out == f"ok  {GOOD / 'device.yaml'} (device: SLG_0.56)\n"


def test_mixed_files_report_every_error_and_a_summary(capsys: pytest.CaptureFixture[str]) -> None:
    bad = [BAD / "layers_period_example.yaml", BAD / "inf.yaml"]
    assert main(["check", str(GOOD / "layers.yaml"), *map(str, bad)]) == 1
    out, err = capsys.readouterr()
    assert out.splitlines() == [f"ok  {GOOD / 'layers.yaml'} (texture: layers)", "3 files checked: 1 ok, 2 with errors"]
    assert err.splitlines() == expected_lines(bad[0]) + expected_lines(bad[1])


def test_quiet_prints_only_errors(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["check", "--quiet", str(GOOD / "grating.yaml"), str(GOOD / "temporal.yaml")]) == 0
    assert capsys.readouterr() == ("", "")
    assert main(["check", "-q", str(GOOD / "grating.yaml"), str(BAD / "nan.yaml")]) == 1
    out, err = capsys.readouterr()
    assert out == "" and err.splitlines() == expected_lines(BAD / "nan.yaml")


def test_check_needs_a_file(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as caught:
        main(["check"])
    assert caught.value.code == 1
    assert "the following arguments are required: FILE" in capsys.readouterr().err


@pytest.mark.parametrize(
    "names",
    [
        ["layers_period_example", "unknown_key_typo", "duplicate_key"],
        ["syntax_error", "alias_bomb", "python_object_tag", "nesting_too_deep"],
        ["npy_pickle", "device_unequal_tables", "device_missing_source", "layers_too_deep"],
    ],
)
def test_subprocess_prints_only_breadcrumbs_and_exits_1(names: list[str]) -> None:
    paths = [BAD / f"{name}.yaml" for name in names]
    result = _run("check", "--quiet", *map(str, paths))
    assert result.returncode == 1
    assert result.stdout == ""
    assert result.stderr.splitlines() == [line for path in paths for line in expected_lines(path)]
    assert "Traceback" not in result.stderr


def test_subprocess_missing_file() -> None:
    result = _run("check", "no/such/file.yaml")
    assert result.returncode == 1
    assert result.stderr == "no/such/file.yaml: cannot read: no such file or directory\n"


def test_plain_when_piped_and_coloured_when_forced() -> None:
    args = ("check", str(GOOD / "grating.yaml"), str(BAD / "nan.yaml"))
    plain = _run(*args)
    assert "\x1b[" not in plain.stdout + plain.stderr
    coloured = _run(*args, FORCE_COLOR="1")
    assert "\x1b[" in coloured.stdout and "\x1b[" in coloured.stderr
    assert coloured.returncode == 1


@pytest.mark.parametrize("kind", ["texture", "device"])
def test_schema_prints_json(kind: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["schema", kind]) == 0
    out = capsys.readouterr().out
    assert json.loads(out) == schema_json(kind)
    assert out.startswith('{\n  "$schema"')


def test_schema_out_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    target = tmp_path / "texture.schema.json"
    assert main(["schema", "texture", "--out", str(target)]) == 0
    size = len(target.read_bytes())
    assert capsys.readouterr().out == f"wrote the JSON Schema of texture files to {target} ({size} bytes)\n"
    assert json.loads(target.read_text()) == schema_json("texture")


def test_schema_out_file_not_writable(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    target = tmp_path / "missing" / "x.json"
    assert main(["schema", "device", "--out", str(target)]) == 1
    assert capsys.readouterr().err == f"tpad-rt schema: {target}: cannot write schemas there: no folder {target.parent}\n"


def test_schema_bad_choice() -> None:
    result = _run("schema", "sound")
    assert result.returncode == 1
    assert "invalid choice: 'sound'" in result.stderr and "Traceback" not in result.stderr


def test_a_file_of_20000_unknown_keys_lists_the_first_100_and_counts_the_rest(tmp_path: Path,
                                                                             capsys: pytest.CaptureFixture[str]) -> None:
    """Issue 20: 20,000 unknown keys took check 30-75 s (each error's line was a scan of the mapping)."""
    from tpad_rt.config.messages import MAX_LISTED_ERRORS

    path = tmp_path / "keys.yaml"
    path.write_text("description: x\nkind: grating\nperiod_mm: 4\nfriction: {low: 0.6, high: 1}\n"
                    + "".join(f"k{index}: 1\n" for index in range(20_000)))
    assert main(["check", str(path)]) == 1
    out, err = capsys.readouterr()
    lines = err.splitlines()
    assert out == "" and len(lines) == MAX_LISTED_ERRORS + 1 and lines[0] == f"{path}: k0: unknown key (line 5)"
    assert lines[-1] == f"{path}: and {20_000 - MAX_LISTED_ERRORS:,} more problems (the first {MAX_LISTED_ERRORS} are " \
        "listed)"
