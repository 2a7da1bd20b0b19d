"""The NUCLEO-G474RE board (firmware/boards/nucleo-g474re): its host register test, that test's power
to catch a wrong register value, the ARM build a user flashes, and the flash target without tools."""

from __future__ import annotations

import fcntl
import re
import struct
import subprocess
from pathlib import Path

from conftest import require_program
from firmware_build import BUILD, FIRMWARE, build, make_target

BOARD = FIRMWARE / "boards" / "nucleo-g474re"
#: RM0440 section 2.2: 512 kB of flash at 0x08000000, 128 kB of SRAM at 0x20000000.
FLASH_START, FLASH_BYTES = 0x0800_0000, 512 * 1024
RAM_START, RAM_BYTES = 0x2000_0000, 128 * 1024
#: RAM left for the stack (bytes): the core's loop and the interrupts need well under this.
MIN_STACK_BYTES = 8 * 1024
#: The vector table: 16 Cortex-M4 exceptions and the G474's 102 interrupts (RM0440 section 14.3).
VECTOR_WORDS = 16 + 102
#: ELF: e_machine of ARM, and the EABI flag of the hard-float calling convention.
EM_ARM = 40
EF_ARM_ABI_FLOAT_HARD = 0x400


def _register_test_sources() -> list[Path]:
    return [FIRMWARE / "tests" / "g4_registers.c", BOARD / "board.c", BOARD / "g4_setup.c"]


def test_register_test_passes() -> None:
    """``make -C firmware test-nucleo-g474re``: hal_init() on RAM-mapped registers, every register the
    set-up writes checked against RM0440's numbers, and the rings driven through the interrupt handlers."""
    done = make_target("test-nucleo-g474re")
    assert done.returncode == 0, done.stdout[-3000:]
    found = re.search(r"g4 registers: (\d+) checks passed", done.stdout)
    assert found is not None, done.stdout[-3000:]
    assert int(found.group(1)) >= 200


def _register_test_with(tmp_path: Path, old: str, new: str) -> subprocess.CompletedProcess[str]:
    """The register test built against g4_setup.c with ``old`` replaced by ``new``, and run."""
    gcc = require_program("gcc")
    wrong = tmp_path / "g4_setup.c"
    source = (BOARD / "g4_setup.c").read_text()
    assert old in source
    wrong.write_text(source.replace(old, new))
    binary = tmp_path / "g4-registers"
    sources = [str(path) for path in _register_test_sources() if path.name != "g4_setup.c"] + [str(wrong)]
    subprocess.run([gcc, "-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "-DG4_REGISTER_TEST",
                    f"-I{FIRMWARE / 'core'}", f"-I{BOARD}", "-O1", "-o", str(binary), *sources],
                   check=True, timeout=120)
    return subprocess.run([str(binary)], capture_output=True, text=True, timeout=60, check=False)


def test_register_test_catches_a_wrong_pll(tmp_path: Path) -> None:
    """The same test built against a set-up whose PLL multiplies by 86 (173 MHz) fails, naming PLLN and
    the PLL's output: the checks are numbers from the manual, not the set-up's own constants."""
    done = _register_test_with(tmp_path, "#define PLL_N 85u", "#define PLL_N 86u")
    assert done.returncode == 1
    assert "FAIL RCC_PLLCFGR.PLLN (x85): 0x56, expected 0x55" in done.stdout
    assert "FAIL PLL output (Hz)" in done.stdout


def test_register_test_catches_a_warm_reset_started_at_0(tmp_path: Path) -> None:
    """A set-up that starts the DAC at code 0 whatever the reset (the step of -1.65 V into the stage's
    coupling capacitor after an IWDG reset, docs/firmware.md "Resets") fails the IWDG reset's check."""
    done = _register_test_with(tmp_path, "if (reset_flags & RCC_CSR_BORRSTF)", "if (reset_flags | 1u)")
    assert done.returncode == 1
    assert "FAIL IWDG reset after start-up: the DAC's first code: 0x0, expected 0x800" in done.stdout
    assert "FAIL power-on" not in done.stdout


def test_arm_build_fits_the_g474_and_boots_from_its_vector_table() -> None:
    """``make -C firmware nucleo-g474re``: a hard-float ARM ELF and its .bin; code and data fit the
    G474RE's flash, data and bss leave the stack room in its SRAM; the .bin starts with the vector
    table (the stack's top, then the reset handler in flash, Thumb)."""
    elf = build("nucleo-g474re")
    size = require_program("arm-none-eabi-size")
    header = elf.read_bytes()[:52]
    assert header[:4] == b"\x7fELF"
    machine, = struct.unpack_from("<H", header, 18)
    flags, = struct.unpack_from("<I", header, 36)
    assert machine == EM_ARM
    assert flags & EF_ARM_ABI_FLOAT_HARD
    done = subprocess.run([size, "-A", str(elf)], capture_output=True, text=True, timeout=60, check=True)
    sections = {parts[0]: (int(parts[1]), int(parts[2])) for parts in
                (line.split() for line in done.stdout.splitlines()) if len(parts) == 3 and parts[1].isdigit()}
    in_flash = sum(length for name, (length, address) in sections.items()
                   if FLASH_START <= address < FLASH_START + FLASH_BYTES)
    data = sections[".data"][0] if ".data" in sections else 0
    bss = sections[".bss"][0] if ".bss" in sections else 0
    assert 0 < in_flash + data <= FLASH_BYTES
    assert data + bss <= RAM_BYTES - MIN_STACK_BYTES
    image = (elf.parent / "tpad-amp.bin").read_bytes()
    vectors = struct.unpack_from(f"<{VECTOR_WORDS}I", image)
    assert vectors[0] == RAM_START + RAM_BYTES
    reset = vectors[1]
    assert reset & 1 and FLASH_START <= reset - 1 < FLASH_START + len(image)


def test_flash_without_its_tools_says_so_in_one_line() -> None:
    """``make flash-nucleo-g474re`` with neither openocd nor st-flash on the machine: one line naming
    both and the Debian packages, and a failed make; nothing is flashed."""
    build("nucleo-g474re")
    with open(BUILD / ".lock", "w") as lock:  # firmware_build's lock: no other make in the tree meanwhile
        fcntl.flock(lock, fcntl.LOCK_EX)
        done = subprocess.run(["make", "-s", "-C", str(FIRMWARE), "flash-nucleo-g474re",
                               "G4_OPENOCD=tpad-no-openocd", "G4_STFLASH=tpad-no-st-flash"],
                              capture_output=True, text=True, timeout=120, check=False)
    assert done.returncode != 0
    ours = [line for line in done.stderr.splitlines() if not line.startswith("make")]
    assert ours == ["flash-nucleo-g474re: neither tpad-no-openocd nor tpad-no-st-flash found "
                    "(Debian: apt install openocd, or stlink-tools)"]
