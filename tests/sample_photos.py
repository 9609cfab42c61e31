"""scikit-image's sample photos (shipped with it; none shows a curved mirror), as the
linear RGB a camera file would give: a plain module (no tests here) for the tests and
scripts that look for mirrors where there are none.
"""

from __future__ import annotations

import numpy as np

#: The sample photos without a mirror that ``--free`` refuses (tests/test_free_no_mirror.py).
FREE_REFUSED = ("brick", "camera", "cat", "grass", "gravel", "immunohistochemistry",
                "page", "rocket", "text")

#: Those in which ``--free`` finds a circle, and what it is: round things, which a search
#: without a setup cannot tell from a mirror's outline.
FREE_ROUND_THINGS = {
    "astronaut": "a circle cut by the frame's bottom (radius 91 px), fitted to 85% of "
                 "its points the photo shows",
    "clock": "the wall clock's face, as a limb: detail along the radius in every sector",
    "coffee": "the coffee cup's rim, an ellipse of axis ratio 0.80",
    "coins": "a coin's edge (radius 29 px), all round",
    "moon": "a crater (radius 25 px), all round",
}


def sample_photo(name: str) -> np.ndarray:
    """scikit-image's sample photo ``name`` (8-bit sRGB, taken as gamma 2.2) as linear
    float32 RGB (H, W, 3); a grey photo is repeated in the three channels."""
    import skimage.data

    img = getattr(skimage.data, name)()
    img = (img.astype(np.float32) / 255.0) ** 2.2
    return np.repeat(img[..., None], 3, axis=-1) if img.ndim == 2 else img[..., :3]
