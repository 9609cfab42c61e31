"""Renamed names keep working for one release (mitsweep.deprecation): the former keyword
or attribute gives the same result with a DeprecationWarning; both at once is an error."""

from dataclasses import dataclass, fields

import numpy as np
import pytest

from mitsweep.deprecation import RENAMED, renamed_fields, renamed_keywords


@renamed_keywords(depth_mm="depth")
def _blur(x, *, depth=500.0):
    return x * depth


@renamed_fields(depth_mm="depth")
@dataclass(frozen=True)
class _Plane:
    depth: float
    name: str = "p"


def test_a_former_keyword_works_and_warns():
    with pytest.warns(DeprecationWarning, match=r"depth_mm=\.\.\.\) is deprecated: use depth="):
        assert _blur(2.0, depth_mm=3.0) == 6.0
    assert _blur(2.0, depth=3.0) == 6.0


def test_both_names_at_once_are_refused():
    with pytest.raises(TypeError, match="give depth or its deprecated name depth_mm"), \
            pytest.warns(DeprecationWarning):
        _blur(1.0, depth=1.0, depth_mm=2.0)
    with pytest.raises(TypeError, match="not both"), pytest.warns(DeprecationWarning):
        _Plane(depth=1.0, depth_mm=2.0)


def test_a_former_field_works_in_the_constructor_and_as_an_attribute():
    with pytest.warns(DeprecationWarning):
        p = _Plane(depth_mm=4.0)
    assert p.depth == 4.0
    with pytest.warns(DeprecationWarning, match=r"_Plane\.depth_mm is deprecated"):
        assert p.depth_mm == 4.0
    # not a field: replace() and asdict() see only the present name
    assert [f.name for f in fields(p)] == ["depth", "name"]


def test_the_renames_are_recorded_for_the_vocabulary_check():
    assert RENAMED[f"{__name__}._Plane.depth_mm"] == "depth"
    assert RENAMED[f"{__name__}._blur(depth_mm)"] == "depth"


def test_a_renamed_keyword_of_the_package_gives_the_same_result():
    """sensor_to_pixel's former ``pitch``: the same pixels as ``pixel_pitch``."""
    from mitsweep.optics.pixels import sensor_to_pixel

    u, v = np.array([0.1, -0.3]), np.array([0.2, 0.05])
    new = sensor_to_pixel(u, v, (64, 48), pixel_pitch=0.01)
    with pytest.warns(DeprecationWarning):
        old = sensor_to_pixel(u, v, (64, 48), pitch=0.01)
    np.testing.assert_array_equal(np.asarray(old), np.asarray(new))
