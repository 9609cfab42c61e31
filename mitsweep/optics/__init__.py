"""Pure NumPy optics of a catadioptric focal-sweep camera (no Mitsuba, no Dr.Jit).

Profiles (sag, slope, curvature, principal radii), placement and tilt, the thin lens,
the chief ray, the generalised Coddington equations and the optimal sweep range.
"""

from .chief_ray import ChiefRay, chief_ray, image_point, intersect_mirror, mirror_point_from_image
from .coddington import coddington_reflection, focal_distances, focal_image_axial_distances
from .kinematics import Trapezoid
from .placement import Placement, SurfacePoints, placement_of
from .pixels import optical_center_px, pixel_to_sensor, sensor_to_pixel
from .profiles import Profile, conic_sag, profile_of
from .reference import ReferenceGeometry, reference_geometry
from .sweep import MirrorZone, SweepRange, max_fov_deg, mirror_zone, optimal_sweep_range
from .thinlens import image_distance, magnification, object_distance

__all__ = [
    "ChiefRay", "chief_ray", "image_point", "intersect_mirror", "mirror_point_from_image",
    "coddington_reflection", "focal_distances", "focal_image_axial_distances",
    "Placement", "SurfacePoints", "placement_of", "Profile", "conic_sag", "profile_of",
    "MirrorZone", "SweepRange", "max_fov_deg", "mirror_zone", "optimal_sweep_range",
    "image_distance", "magnification", "object_distance", "Trapezoid",
    "optical_center_px", "pixel_to_sensor", "sensor_to_pixel", "ReferenceGeometry",
    "reference_geometry",
]
