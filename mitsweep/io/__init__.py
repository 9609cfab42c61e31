"""File formats at the edge of the package: EXR images with metadata, atomic writes,
directory locks."""

from .atomic import WriteError, atomic_path, write_bytes_atomic, write_text_atomic
from .exr import ExrError, read_exr, read_exr_header, write_exr

__all__ = ["WriteError", "atomic_path", "write_bytes_atomic", "write_text_atomic", "ExrError",
           "read_exr", "read_exr_header", "write_exr"]
