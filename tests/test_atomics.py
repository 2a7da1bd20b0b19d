"""Release stores and acquire loads (tpad_rt.kernel.atomics): the Python side's publications to the
audio callback, and the callback's reads of them, compile to atomic accesses with those orderings."""

from __future__ import annotations

import numba
import numpy as np
import pytest
from numba.core.errors import TypingError

from tpad_rt.kernel import atomics
from tpad_rt.kernel import callback as cb


def _atomic_lines(llvm_ir: str) -> list[str]:
    return [line.strip() for line in llvm_ir.splitlines() if "atomic i64" in line]


def _fresh_cfunc_llvm(callback: numba.core.ccallback.CFunc) -> str:
    """The LLVM IR of ``callback`` compiled anew (numba shows no IR for code loaded from its disk cache)."""
    return numba.cfunc(cb._SIGNATURE, nopython=True, error_model="numpy")(callback._pyfunc).inspect_llvm()


def test_publish_stores_the_value_with_a_release_store() -> None:
    array = np.zeros(4, dtype=np.int64)
    atomics.publish(array, 2, 7)
    assert array.tolist() == [0, 0, 7, 0]
    fresh = numba.njit(nogil=True)(atomics._publish.py_func)
    fresh(array, np.int64(0), np.int64(0))
    llvm_ir = fresh.inspect_llvm(fresh.signatures[0])
    assert any(line.startswith("store atomic i64") and " release," in line for line in _atomic_lines(llvm_ir))


def test_publish_is_a_plain_store_without_the_jit(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(numba.config, "DISABLE_JIT", True)
    array = np.zeros(2, dtype=np.int64)
    atomics.publish(array, 1, -3)
    assert array.tolist() == [0, -3]


def test_the_render_callback_acquires_the_finger_count_and_the_texture_slot() -> None:
    loads = [line for line in _atomic_lines(_fresh_cfunc_llvm(cb.render_callback)) if "load atomic i64" in line]
    assert len(loads) == 2 and all(" acquire," in line for line in loads)  # about 20 s to compile
    silent = [line for line in _atomic_lines(_fresh_cfunc_llvm(cb.silence_callback)) if "load atomic i64" in line]
    assert len(silent) == 1  # the finger count it records


def test_acquire_loads_read_what_was_stored_and_only_take_int64_vectors() -> None:
    @numba.njit
    def round_trip(array: np.ndarray, index: int, value: int) -> int:
        atomics.store_release(array, index, value)
        return atomics.load_acquire(array, index)

    assert round_trip(np.zeros(3, dtype=np.int64), 1, 42) == 42

    @numba.njit
    def on_floats(array: np.ndarray) -> float:
        return atomics.load_acquire(array, 0)

    with pytest.raises(TypingError):
        on_floats(np.zeros(3))
