"""Peak memory of a call: NumPy's (tracemalloc) plus Dr.Jit's (its allocator's
watermark), for estimates that must cover both. Their sum bounds the true peak from
above (the two peaks need not coincide), so an estimate at least the sum covers it."""

import sys
import tracemalloc


def _jit_backends():
    if "drjit" not in sys.modules:
        return None, []
    import drjit as dr

    return dr, [b for b in (dr.JitBackend.LLVM, dr.JitBackend.CUDA) if dr.has_backend(b)]


def traced_peak(fn) -> int:
    """Bytes: tracemalloc's peak during ``fn()`` plus Dr.Jit's watermark above what it
    held before (every backend with a device)."""
    dr, backends = _jit_backends()
    before = 0
    if dr is not None:
        dr.sync_thread()
        # blocks freed by earlier work wait in Dr.Jit's cache; a call served from it would
        # not raise the watermark (a fresh-clone CI measured 4.7 MB against 8-13 MB): free
        # them, so the call's arrays are counted whatever ran before in this process
        dr.flush_malloc_cache()
        dr.detail.malloc_clear_statistics()
        before = sum(dr.detail.malloc_watermark(b) for b in backends)
    tracemalloc.start()
    try:
        fn()
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    dr, backends = _jit_backends()          # fn may have imported it
    if dr is not None:
        dr.sync_thread()
        after = sum(dr.detail.malloc_watermark(b) for b in backends)
        peak += max(0, after - before)
    return peak
