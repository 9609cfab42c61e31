"""File formats at the edge of the package: EXR images with metadata, camera files
(RAW, TIFF, PNG, JPEG) and display images, atomic writes, directory locks."""

from .atomic import WriteError, atomic_path, write_bytes_atomic, write_text_atomic
from .camera import CameraFileError, CameraImage, read_camera_image, write_display_image
from .exr import ExrError, read_exr, read_exr_header, stack_channels, write_exr

__all__ = ["WriteError", "atomic_path", "write_bytes_atomic", "write_text_atomic", "ExrError",
           "read_exr", "read_exr_header", "stack_channels", "write_exr", "CameraFileError",
           "CameraImage", "read_camera_image", "write_display_image"]
